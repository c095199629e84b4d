"""The simulator node's machinery that needs no ROS: the wall-clock loop thread and its timing
(:mod:`.loop`), the bounded command intake with coalescing and throttled refusal reports (:mod:`.intake`),
and the diagnostics arithmetic as a side-effect-free function (:mod:`.diagnostics`).

The simulator's engine (:mod:`micro_feeder.sim.engine`) drives these and ``nodes/simulator.py`` wires it to rclpy;
everything here can be driven and tested without it.
"""
