"""The vendored standard interfaces (interfaces/) are generated into this venv and declared for ROS 2 installs."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_generated_types_import_and_serialize() -> None:
    """`make` built them into the venv: the types import, and a message goes through rclpy's serializer."""
    from control_msgs.action import FollowJointTrajectory
    from rclpy.serialization import deserialize_message, serialize_message
    from simulation_interfaces.action import SimulateSteps
    from simulation_interfaces.msg import SimulatorFeatures
    from simulation_interfaces.srv import GetSimulatorFeatures

    single = SimulatorFeatures.STEP_SIMULATION_SINGLE
    response = GetSimulatorFeatures.Response(features=SimulatorFeatures(features=[single]))
    again = deserialize_message(serialize_message(response), GetSimulatorFeatures.Response)
    assert list(again.features.features) == [single]
    assert FollowJointTrajectory.Result.INVALID_JOINTS == -2
    assert SimulateSteps.Goal().steps == 0


def test_package_xml_depends_on_the_distributions_packages() -> None:
    """A colcon workspace takes the distribution's packages (declared), never builds the vendored copies."""
    depends = {e.text for e in ET.parse(ROOT / 'package.xml').getroot().iter('depend')}
    assert {'simulation_interfaces', 'control_msgs'} <= depends
    assert (ROOT / 'interfaces' / 'COLCON_IGNORE').exists()
    for package in ('simulation_interfaces', 'control_msgs'):
        assert (ROOT / 'interfaces' / package / 'LICENSE').stat().st_size > 0
