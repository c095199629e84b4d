"""JointTrajectory CDR with numpy: the bytes rclpy reads back, and the same checked command as rclpy's
deserialization followed by ``parse_trajectory`` (the reference), for every layout."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from rclpy.serialization import deserialize_message, serialize_message
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from micro_feeder.interface import messages, stamps, trajectory_cdr
from micro_feeder.sim.commands import CommandRejected, parse_trajectory, parse_trajectory_cdr

LIMITS = (-200e-6, 200e-6)


def _knots(n_points: int, n_joints: int, seed: int = 0) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    offsets = np.cumsum(rng.integers(1, 2_500_000_000, n_points))
    return offsets, rng.uniform(-1e-4, 1e-4, (n_points, n_joints)), rng.normal(size=(n_points, n_joints)), \
        rng.normal(size=(n_points, n_joints)) * 1e3


@pytest.mark.parametrize('names', [['piezo_0'], ['piezo_1', 'piezo_0'], ['abc', 'de', 'f'],
                                   [f'piezo_{i}' for i in range(64)]])
@pytest.mark.parametrize('n_points', [0, 1, 2, 7])
def test_encoded_bytes_deserialize_to_the_message(names: list[str], n_points: int) -> None:
    offsets, pos, vel, acc = _knots(n_points, len(names))
    stamp = stamps.to_time(12.345678901)
    data = trajectory_cdr.encode(names, offsets, pos, vel, acc, stamp)
    assert deserialize_message(data, JointTrajectory) == messages.trajectory(names, offsets * 1e-9, pos, vel, acc,
                                                                             stamp)


def _same(a, b) -> None:
    assert a.stamp == b.stamp
    for x, y in ((a.offsets, b.offsets), (a.positions, b.positions), (a.velocities, b.velocities),
                 (a.accelerations, b.accelerations)):
        assert (x is None and y is None) or np.array_equal(x, y)


@pytest.mark.parametrize('names', [['piezo_0'], ['piezo_0', 'piezo_1'], ['piezo_1', 'piezo_0'],
                                   ['piezo_2', 'piezo_0', 'piezo_1']])
def test_parse_from_bytes_equals_parse_of_the_deserialized_message(names: list[str]) -> None:
    """1 and 3 joints put the first knot's doubles on an 8-byte boundary (read as a view of the bytes), 2
    joints need the padding that splits it (joined in a copy)."""
    joints = sorted(names)
    offsets, pos, vel, acc = _knots(50, len(names))
    for data in (trajectory_cdr.encode(names, offsets, pos, vel, acc, stamps.to_time(3.0)),
                 serialize_message(messages.trajectory(names, offsets * 1e-9, pos, vel, acc, stamps.to_time(3.0)))):
        _same(parse_trajectory_cdr(data, joints, LIMITS),
              parse_trajectory(deserialize_message(data, JointTrajectory), joints, LIMITS))
    positions_only = JointTrajectory(joint_names=names, points=[   # another layout: rclpy's path
        JointTrajectoryPoint(positions=list(p), time_from_start=Duration(nanosec=int(t)))
        for t, p in zip(offsets[:5], pos[:5], strict=True)])
    data = serialize_message(positions_only)
    _same(parse_trajectory_cdr(data, joints, LIMITS), parse_trajectory(positions_only, joints, LIMITS))


def test_bad_bytes_and_bad_values_are_refused_with_the_reason() -> None:
    offsets, pos, vel, acc = _knots(5, 1)
    data = trajectory_cdr.encode(['piezo_0'], offsets, pos, vel, acc, stamps.to_time(0.0))
    for garbage in (b'', b'\x00\x01\x00\x00' + b'\xff' * 40, data[:-20]):
        with pytest.raises(CommandRejected, match='cannot deserialize'):
            parse_trajectory_cdr(garbage, ['piezo_0'], LIMITS)
    vel[2, 0] = 1e300
    data = trajectory_cdr.encode(['piezo_0'], offsets, pos, vel, acc, stamps.to_time(0.0))
    with pytest.raises(CommandRejected, match='velocity 1e\\+300'):
        parse_trajectory_cdr(data, ['piezo_0'], LIMITS)
    with pytest.raises(CommandRejected, match='unknown joint'):
        parse_trajectory_cdr(trajectory_cdr.encode(['x'], offsets, pos, vel * 0, acc, stamps.to_time(0.0)),
                             ['piezo_0'], LIMITS)


def test_a_million_points_are_refused_without_reading_them() -> None:
    head = trajectory_cdr.encode(['piezo_0'], np.zeros(0, dtype=np.int64), np.zeros((0, 1)), np.zeros((0, 1)),
                                 np.zeros((0, 1)), stamps.to_time(0.0))
    data = head[:-4] + struct.pack('<I', 1_000_000) + bytes(64)        # claims a million points
    start = time.perf_counter()
    with pytest.raises(CommandRejected, match='1000000 points, more than'):
        parse_trajectory_cdr(data, ['piezo_0'], LIMITS)
    assert time.perf_counter() - start < 0.1
