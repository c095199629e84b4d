"""The simulator's per-tick state messages are patched CDR templates (interface/messages.py): what a subscriber
deserializes must be exactly the observation, tick after tick, for any number of joints."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray, PoseStamped, TwistStamped, WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header
from visualization_msgs.msg import Marker, MarkerArray

from micro_feeder.interface.messages import StateMessages, SurfaceMarkers, header_bytes, tilt_quaternion
from micro_feeder.interface.parts_messages import MODE_CODES, PART_STATE_FIELDS, PartsMessages
from micro_feeder.interface.stamps import seconds, to_time
from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.dynamics.model import StateRows


@pytest.mark.parametrize('n_actuators', [1, 3, 64])
def test_serialized_state_equals_the_observation(n_actuators):
    centers = tuple(1e-3 * k for k in range(n_actuators))
    model = FeederModel()
    model = model.replace(surface=model.surface.replace(centers=centers, widths=(1e-3,) * n_actuators),
                          stroke=model.stroke.replace(phases=tuple(k / n_actuators for k in range(n_actuators))))
    names = [f'joint_{k}' for k in range(n_actuators)]
    state_messages = StateMessages(names)
    state = model.initial_state()
    rng = np.random.default_rng(n_actuators)
    for t in (1e-4, 3.3e-4, 7e-4, 1.2e-3, 2.000000001):
        model.advance(state, t)
        obs = model.observe(state)
        velocities = rng.normal(size=n_actuators)
        stamp = state_messages.update(obs, velocities)
        assert seconds(stamp) == pytest.approx(t, abs=1e-9)
        pose = deserialize_message(state_messages.pose, PoseStamped)
        twist = deserialize_message(state_messages.twist, TwistStamped)
        wrench = deserialize_message(state_messages.wrench, WrenchStamped)
        joints = deserialize_message(state_messages.joints, JointState)
        clock = deserialize_message(state_messages.clock, Clock)
        for header in (pose.header, twist.header, wrench.header, joints.header):
            assert (header.stamp.sec, header.stamp.nanosec) == (stamp.sec, stamp.nanosec)
        assert (clock.clock.sec, clock.clock.nanosec) == (stamp.sec, stamp.nanosec)
        assert (pose.header.frame_id, wrench.header.frame_id) == ('feeder', 'contact')
        q = pose.pose.orientation
        assert (pose.pose.position.x, pose.pose.position.y, pose.pose.position.z) == (obs.x, 0.0, obs.z)
        assert (q.x, q.y, q.z, q.w) == tilt_quaternion(obs.theta)
        assert (twist.twist.linear.x, twist.twist.linear.z, twist.twist.angular.y) == (obs.xdot, obs.zdot, 0.0)
        assert (wrench.wrench.force.x, wrench.wrench.force.z) == (obs.friction, obs.normal_load)
        assert list(joints.name) == names and list(joints.effort) == []
        assert list(joints.position) == list(obs.strokes) and list(joints.velocity) == list(velocities)


def test_a_run_of_the_wrong_length_is_refused():
    model = FeederModel()
    model = model.replace(surface=model.surface.replace(centers=(0.0, 1e-3), widths=(1e-3, 1e-3)),
                          stroke=model.stroke.replace(phases=(0.0, 0.5)))
    state_messages = StateMessages(['joint_0', 'joint_1'])
    obs = model.observe(model.initial_state())
    with pytest.raises(ValueError, match='1 values for a run of 2'):
        state_messages.update(obs, np.zeros(1))           # would otherwise broadcast silently
    with pytest.raises(ValueError, match='3 values for a run of 2'):
        state_messages.update(obs, np.zeros(3))


@pytest.mark.parametrize('n_actuators', [1, 5])
def test_serialized_markers_draw_the_surface_and_the_part(n_actuators):
    centers = tuple(1e-3 * k for k in range(n_actuators))
    widths = tuple(1e-3 * (1 + k / 10) for k in range(n_actuators))
    model = FeederModel()
    model = model.replace(surface=model.surface.replace(centers=centers, widths=widths),
                          stroke=model.stroke.replace(phases=tuple(k / n_actuators for k in range(n_actuators))))
    xs = np.linspace(-4e-3, 1e-2, 50)
    markers = SurfaceMarkers(xs, centers, widths, 1e-4)
    state = model.initial_state()
    modes = set()
    for t in (2e-4, 4.5e-4, 7e-4, 1.3e-3, 3.000000001):
        model.advance(state, t)
        obs = model.observe(state)
        stamp = to_time(obs.t)
        got = deserialize_message(markers.update(obs, stamp), MarkerArray)
        modes.add(obs.mode)
        line, part = got.markers
        for marker in (line, part):
            assert (marker.header.stamp.sec, marker.header.stamp.nanosec) == (stamp.sec, stamp.nanosec)
            assert (marker.header.frame_id, marker.ns, marker.action) == ('feeder', 'micro_feeder', Marker.ADD)
        assert (line.id, line.type, part.id, part.type) == (0, Marker.LINE_STRIP, 1, Marker.SPHERE)
        # the surface: the sum of the Gaussian bumps, evaluated here independently
        expected = [sum(s * math.exp(-0.5 * ((x - c) / w) ** 2)
                        for s, c, w in zip(obs.strokes, centers, widths, strict=True)) for x in xs]
        assert [p.x for p in line.points] == list(xs) and {p.y for p in line.points} == {0.0}
        np.testing.assert_allclose([p.z for p in line.points], expected, rtol=1e-12, atol=1e-18)
        position = part.pose.position
        assert (position.x, position.y, position.z) == (obs.x, 0.0, obs.z + 0.5e-4)
        assert part.scale.x == part.scale.y == part.scale.z == 1e-4
        assert (part.color.r, part.color.g, part.color.b) == pytest.approx(
            {'stuck': (0.2, 0.7, 0.2), 'sliding': (0.9, 0.6, 0.1)}.get(obs.mode, (0.9, 0.2, 0.2)))
    assert modes == {'stuck', 'sliding'}       # both colours drawn


@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc', 'abcd', '/feeder1/actuator/command', 'µ-stage'])
def test_header_bytes_are_what_rclpy_serializes(frame_id):
    for t in (0.0, 1e-9, 0.0123456789, 3.9999999999, 12345.000000001):
        expected = Header(stamp=to_time(t), frame_id=frame_id)
        assert header_bytes(t, frame_id) == serialize_message(expected)
        assert deserialize_message(header_bytes(t, frame_id), Header) == expected


def test_every_parts_messages_hold_each_parts_observation():
    """particles/poses and particles/states are written from the rows of one compiled call (no Observation
    per part): what a subscriber deserializes is each part's observation, part after part, stuck, sliding and
    in flight, tick after tick."""
    model = FeederModel()
    states = [model.initial_state(0.5e-3), model.initial_state(1.5e-3, 0.02),
              model.flying_state(2.5e-3, 3e-6, 0.01, 0.2)]
    messages = PartsMessages(len(states))
    for t in (1e-4, 7e-4, 2.3e-3):
        for state in states:
            model.advance(state, t)
        observed = model.observe_rows(StateRows.of(states))
        assert [observed[i].mode for i in range(3)] == [state.mode for state in states]
        messages.update(observed)
        poses = deserialize_message(messages.poses, PoseArray)
        table = np.asarray(deserialize_message(messages.states, Float64MultiArray).data).reshape(3, -1)
        assert seconds(poses.header.stamp) == pytest.approx(t, abs=1e-9)
        for i, (pose, row) in enumerate(zip(poses.poses, table, strict=True)):
            obs = observed[i]
            orientation = (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w)
            assert (pose.position.x, pose.position.y, pose.position.z) == (obs.x, 0.0, obs.z)
            assert orientation == tilt_quaternion(obs.theta)
            expected = {'t': obs.t, 'mode': MODE_CODES[obs.mode], 'x': obs.x, 'xdot': obs.xdot, 'z': obs.z,
                        'zdot': obs.zdot, 'normal_load': obs.normal_load, 'friction': obs.friction}
            assert row.tolist() == [expected[field] for field in PART_STATE_FIELDS]
