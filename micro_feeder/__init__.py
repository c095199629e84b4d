"""micro_feeder: simulator of a piezo-actuated micro-part feeder (ROS 2, Python)."""

__version__ = '0.1.0'
