"""Test session set-up: ROS traffic on loopback only, a random domain, logs in a temp dir.

Set before any test imports rclpy, so every Context and every child process inherits them.
"""

import os
import random
import tempfile

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(1, 100))
os.environ['ROS_LOG_DIR'] = tempfile.mkdtemp(prefix='micro-feeder-roslog-')
os.environ.setdefault('MPLBACKEND', 'Agg')
pytest_plugins = ['ros_helpers']

# The physics kernel compiles once per installation (~10 min, docs/dynamics.md §6): here, before any test
# and outside the per-test timeout, rather than inside whichever test integrates first (~1.5 s once cached).
# One part and several (the parts' batched call) both.
from micro_feeder.physics.dynamics import FeederModel  # noqa: E402
from micro_feeder.physics.parts import PartsModel  # noqa: E402

FeederModel().run()
PartsModel.from_settings({'particle.x0': [0.0, 0.5e-3]}).run(1e-3)
