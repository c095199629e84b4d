"""The micro_feeder topics (docs/interface.md), with their types and the QoS their publishers offer.

Plain data (no rclpy) so that the logs library, the nodes and the tests share one table. Names are
relative (``particle/pose``) so that a node namespace applies; ``/clock`` and ``/diagnostics`` are
absolute by ROS convention.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TopicSpec:
    """One topic: name, ``pkg/msg/Type``, and QoS (reliable or best effort, transient local or
    volatile, keep-last depth)."""

    name: str
    type: str
    reliable: bool = True
    transient_local: bool = False
    depth: int = 10


TOPICS: tuple[TopicSpec, ...] = (
    TopicSpec('actuator/trajectory', 'trajectory_msgs/msg/JointTrajectory', depth=10),
    TopicSpec('actuator/command', 'std_msgs/msg/Float64MultiArray', depth=10),
    TopicSpec('actuator/joint_states', 'sensor_msgs/msg/JointState', depth=100),
    TopicSpec('particle/pose', 'geometry_msgs/msg/PoseStamped', depth=100),
    TopicSpec('particle/twist', 'geometry_msgs/msg/TwistStamped', depth=100),
    TopicSpec('particle/contact_wrench', 'geometry_msgs/msg/WrenchStamped', depth=100),
    TopicSpec('particle/contact_state', 'std_msgs/msg/String', transient_local=True, depth=1000),
    TopicSpec('particle/transitions', 'diagnostic_msgs/msg/DiagnosticArray', depth=1000),
    TopicSpec('particles/poses', 'geometry_msgs/msg/PoseArray', depth=100),
    TopicSpec('particles/states', 'std_msgs/msg/Float64MultiArray', depth=100),
    TopicSpec('particles/transitions', 'diagnostic_msgs/msg/DiagnosticArray', depth=1000),
    TopicSpec('surface/markers', 'visualization_msgs/msg/MarkerArray', depth=1),
    TopicSpec('simulator/parameters', 'rcl_interfaces/msg/ParameterEvent', transient_local=True, depth=1),
    TopicSpec('simulator/command_receipts', 'std_msgs/msg/Header', depth=100),
    TopicSpec('simulator/trajectories_received', 'trajectory_msgs/msg/JointTrajectory', depth=100),
    TopicSpec('simulator/command_status', 'diagnostic_msgs/msg/DiagnosticArray', depth=100),
    TopicSpec('simulator/entity_changes', 'diagnostic_msgs/msg/DiagnosticArray', transient_local=True, depth=1000),
    TopicSpec('/clock', 'rosgraph_msgs/msg/Clock', reliable=False, depth=1),
    TopicSpec('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', depth=10),
)

TOPICS_BY_NAME = {spec.name: spec for spec in TOPICS}

COMMAND_TOPICS = ('actuator/trajectory', 'actuator/command')   # what the simulator takes commands on
ENTITY_CHANGES = 'simulator/entity_changes'     # parts spawned and deleted (SpawnEntity, DeleteEntity), for resim
# The simulator's copy of every message it received on a command topic, as received: in a log it holds the
# commands of senders the recorder had not discovered yet (a sender's first burst, on a loaded machine).
RECEIVED_COPIES = {'actuator/trajectory': 'simulator/trajectories_received'}

