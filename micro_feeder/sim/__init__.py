"""The simulation core, no ROS: the session that steps a model under a command schedule (:mod:`.stepper`),
command parsing and checks (:mod:`.commands`), what the simulator does with each command it receives
(:mod:`.session`) and the simulator itself, run in real time or step by step (:mod:`.engine`), the stroke
stream an actuator sends (:mod:`.stream`), and the replay of a log's commands (:mod:`.replay`) that ``resim``
(:mod:`.resim`) and calibration share.

Every path runs on it: offline scripts, sweeps and Dask workers, ``resim``, calibration and the rclpy nodes,
which are thin shells around these objects.
"""
