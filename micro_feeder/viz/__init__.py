"""Live view of a running simulation (or a replay) in Foxglove.

* :mod:`.scene`: the feeder as a native Foxglove 3D scene (``foxglove.SceneUpdate``) and the ``contact``
  frame (``foxglove.FrameTransforms``), built from plain numbers. No ROS.
* :mod:`.endpoint`: ``[HOST:]PORT`` parsing; loopback unless a host is given. No ROS.
* :mod:`.viewer`: the foxglove-sdk WebSocket server that forwards what rclpy nodes publish (their ROS 2
  schemas and CDR bytes), the scene, and sim time (the protocol's ``time`` capability).
"""
