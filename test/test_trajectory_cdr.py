"""JointTrajectory CDR with numpy: the bytes rclpy reads back, and the same checked command as rclpy's
deserialization followed by ``parse_trajectory`` (the reference), for every layout."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header
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


@st.composite
def trajectories(draw) -> JointTrajectory:
    """JointTrajectories as any sender may write them: the joints in any order (sometimes a wrong name),
    each point with positions, velocities, accelerations and efforts of n, 0 or another number of values
    (mostly the same fields on every point), times mostly increasing, values mostly within the limits."""
    n = draw(st.integers(1, 4))
    names = draw(st.permutations([f'piezo_{i}' for i in range(n)]))
    if draw(st.integers(0, 9)) == 0:
        names[0] = 'elbow'
    n_points = draw(st.integers(0, 6))
    usual = draw(st.sampled_from([(n, n, n, 0), (n, n, 0, 0), (n, 0, 0, 0), (n, 0, n, 0), (n, n, n, n)]))
    values = st.floats(-1.5e-4, 1.5e-4) if draw(st.booleans()) else st.floats(allow_nan=True)
    points, t = [], draw(st.integers(0, 10**9))
    for _ in range(n_points):
        lengths = usual if draw(st.integers(0, 7)) else draw(st.tuples(*[st.sampled_from([0, n, n + 1])] * 4))
        arrays = [draw(st.lists(values, min_size=k, max_size=k)) for k in lengths]
        t += draw(st.integers(-10, 3 * 10**9))
        points.append(JointTrajectoryPoint(positions=arrays[0], velocities=arrays[1], accelerations=arrays[2],
                                           effort=arrays[3], time_from_start=Duration(sec=t // 10**9,
                                                                                      nanosec=t % 10**9)))
    return JointTrajectory(header=Header(stamp=stamps.to_time(draw(st.floats(0, 100))), frame_id='a#1'),
                           joint_names=names, points=points)


def _outcome(parse, *args):
    try:
        return parse(*args)
    except CommandRejected as err:
        return str(err)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trajectories())
@example(JointTrajectory(joint_names=['piezo_0'], points=[JointTrajectoryPoint(positions=[0.0, 0.0])]))
def test_every_layout_parses_from_bytes_as_from_the_message(msg: JointTrajectory) -> None:
    """Whatever fields the points carry, reading the bytes gives the command (or the refusal) rclpy's
    deserialization followed by parse_trajectory gives."""
    joints = [f'piezo_{i}' for i in range(len(msg.joint_names))]
    from_bytes = _outcome(parse_trajectory_cdr, serialize_message(msg), joints, LIMITS)
    reference = _outcome(parse_trajectory, msg, joints, LIMITS)
    if isinstance(reference, str):
        assert from_bytes == reference
    else:
        assert not isinstance(from_bytes, str), from_bytes
        _same(from_bytes, reference)
        assert from_bytes.command_id == reference.command_id


@pytest.mark.parametrize('fields', [(True, True, True), (True, True, False), (True, False, False)])
def test_the_usual_layouts_are_read_without_rclpy(fields: tuple[bool, bool, bool]) -> None:
    """Positions with velocities and accelerations (the actuator), with velocities, or alone: read from the
    bytes (the flood of a controller sending positions and velocities costs no rclpy deserialization)."""
    offsets, pos, vel, acc = _knots(5, 3)
    msg = JointTrajectory(joint_names=['piezo_0', 'piezo_1', 'piezo_2'], points=[JointTrajectoryPoint(
        positions=list(p), velocities=list(v) if fields[1] else [], accelerations=list(a) if fields[2] else [],
        time_from_start=Duration(sec=int(t) // 10**9, nanosec=int(t) % 10**9))
        for t, p, v, a in zip(offsets, pos, vel, acc, strict=True)])
    decoded = trajectory_cdr.decode(serialize_message(msg), 100)
    assert decoded is not None and decoded.records is not None
    assert sorted(decoded.records) == sorted(['sec', 'nanosec'] + [f for f, has in zip(
        ('pos', 'vel', 'acc'), fields, strict=True) if has])
