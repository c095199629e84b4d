"""The ROS interface of docs/interface.md as plain data and byte codecs, no rclpy: the topics and their QoS
(:mod:`.topics`), the names of modes, transition kinds, frames and joints (:mod:`.names`), sim-time stamps
(:mod:`.stamps`), the simulator's messages built from an observation (:mod:`.messages`) and the hand-written
CDR codecs of the hot paths (:mod:`.cdr`, :mod:`.trajectory_cdr`, :mod:`.transitions`; :mod:`.wire` picks
them or rclpy's own serialization).
"""
