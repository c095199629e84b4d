"""Building logs with real CDR bytes (rclpy's serializer) for the logs, recorder and replay tests."""

from __future__ import annotations

from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from micro_feeder.logs.writer import LogWriter

T0 = 1_700_000_000_000_000_000  # ns: a fixed receive-time origin
MODES = ('stuck', 'sliding', 'flying')


def pose(i: int) -> PoseStamped:
    m = PoseStamped()
    m.header.frame_id = 'feeder'
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(i * 1_000_000, 1_000_000_000)
    m.pose.position.x, m.pose.position.z = i * 1e-6, (i % 7) * 1e-7
    return m


def one_of_each() -> dict[str, object]:
    """One message of every type the recorder records by default (non-trivial field values)."""
    traj = JointTrajectory(joint_names=['piezo_0', 'piezo_1'])
    # Every sequence filled: rosbags 0.11.9 cannot decode rclpy's CDR of a point whose trailing float64
    # sequences are empty ('CDR message size mismatch'); mcap-ros2-support can (test_logs checks it).
    traj.points = [JointTrajectoryPoint(positions=[1e-6, 2e-6], velocities=[0.1, 0.2], accelerations=[0.0, 0.0],
                                        effort=[0.0, 0.0])]
    traj.points[0].time_from_start.nanosec = 500
    twist = TwistStamped()
    twist.twist.linear.x = 0.25
    wrench = WrenchStamped()
    wrench.wrench.force.x, wrench.wrench.force.z = 1e-6, -3e-6
    markers = MarkerArray(markers=[Marker(ns='micro_feeder', id=3, type=Marker.LINE_STRIP)])
    diag = DiagnosticArray(status=[DiagnosticStatus(name='sim', values=[KeyValue(key='rtf', value='1.0')])])
    clock = Clock()
    clock.clock.sec = 12
    return {
        '/actuator/trajectory': traj, '/actuator/command': Float64MultiArray(data=[1.5e-6, -2.0]),
        '/particle/pose': pose(42), '/particle/twist': twist, '/particle/contact_wrench': wrench,
        '/particle/contact_state': String(data='sliding'), '/surface/markers': markers,
        '/clock': clock, '/diagnostics': diag,
    }


def type_name(msg: object) -> str:
    module = type(msg).__module__.split('.')[0]
    return f'{module}/msg/{type(msg).__name__}'


def write_motion_log(path: Path, n: int = 300, period_ns: int = 1_000_000, **writer_args) -> list[bytes]:
    """A log of ``n`` poses/twists/wrenches at ``period_ns`` and a mode change every 100; returns the
    pose bytes in order."""
    writer = LogWriter(path, **writer_args)
    writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
    writer.add_topic('/particle/twist', 'geometry_msgs/msg/TwistStamped')
    writer.add_topic('/particle/contact_wrench', 'geometry_msgs/msg/WrenchStamped')
    writer.add_topic('/particle/contact_state', 'std_msgs/msg/String')
    poses = []
    for i in range(n):
        t = T0 + i * period_ns
        data = serialize_message(pose(i))
        poses.append(data)
        writer.write('/particle/pose', data, t)
        twist = TwistStamped()
        twist.header.stamp = pose(i).header.stamp
        twist.twist.linear.x = 1e-3
        writer.write('/particle/twist', serialize_message(twist), t + 1)
        wrench = WrenchStamped()
        wrench.header.stamp = pose(i).header.stamp
        wrench.wrench.force.x, wrench.wrench.force.z = 1e-7 * i, 2e-6
        writer.write('/particle/contact_wrench', serialize_message(wrench), t + 2)
        if i % 100 == 0:
            writer.write('/particle/contact_state', serialize_message(String(data=MODES[i // 100 % 3])), t + 3)
    writer.close()
    return poses


def chunks_of(path: Path) -> list[tuple[int, int, list[bytes]]]:
    """(start offset, end offset, message bytes) of every chunk of a complete file, as the mcap library
    (not our reader) reads them."""
    with open(path, 'rb') as stream:
        out = []
        for index in make_reader(stream).get_summary().chunk_indexes:
            stream.seek(index.chunk_start_offset + 9)
            chunk = Chunk.read(ReadDataStream(stream))
            out.append((index.chunk_start_offset, index.chunk_start_offset + index.chunk_length,
                        [r.data for r in breakup_chunk(chunk, validate_crc=True) if isinstance(r, Message)]))
    return out


def rewrite_with_rosbags(source: Path, target: Path) -> None:
    """The same messages (bytes, topics, types, definitions, offered QoS, receive times) written by
    ``rosbags``' rosbag2 writer (MCAP storage): a log from another recorder, whose MCAP publish time is not
    the header stamp."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    with AnyReader([source]) as reader, Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        out = {}
        for c in reader.connections:
            out[c.id] = writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data,
                                              rihs01=reader.typestore.hash_rihs01(c.msgtype),
                                              offered_qos_profiles=c.ext.offered_qos_profiles)
        for c, t, raw in reader.messages():
            writer.write(out[c.id], t, raw)


def write_run_log(path: Path, *, first: int = 0, n: int = 100, trajectories: int = 0, receipts: int = 0,
                  diag_commands: int | None = None, lost: int = 0, refused: int = 0) -> None:
    """A log as the recorder writes it of a simulator run at 1 kHz: poses from sim time ``first`` ms (a
    recorder that joined late starts later than 0), the last ``trajectories`` of the commands on
    ``actuator/trajectory``, ``receipts`` of them acknowledged on ``simulator/command_receipts``, the
    simulator's ``commands_received`` on ``/diagnostics`` (``diag_commands``; none when None), and the
    recorder's counters (``lost`` messages of actuator/trajectory lost while recording); ``refused`` poses the
    middleware refused to take from the simulator (its /diagnostics, with ``diag_commands``)."""
    from std_msgs.msg import Header

    writer = LogWriter(path)
    writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
    t = T0
    for i in range(first, first + n):
        t = T0 + (i - first) * 1_000_000
        writer.write('/particle/pose', serialize_message(pose(i)), t)
    traj = one_of_each()['/actuator/trajectory']
    for k in range(trajectories):
        writer.add_topic('/actuator/trajectory', type_name(traj))
        writer.write('/actuator/trajectory', serialize_message(traj), T0 + k * 10_000_000 + 1)
    for k in range(receipts):
        receipt = Header(frame_id='actuator/trajectory')
        receipt.stamp.nanosec = (first + k * 10) * 1_000_000
        writer.add_topic('/simulator/command_receipts', 'std_msgs/msg/Header')
        writer.write('/simulator/command_receipts', serialize_message(receipt), T0 + k * 10_000_000 + 2)
    if diag_commands is not None:
        diag = DiagnosticArray(status=[DiagnosticStatus(name='simulator: loop', values=[
            KeyValue(key='commands_received', value=str(diag_commands)),
            KeyValue(key='publishes_refused', value=str(refused)),
            *([KeyValue(key='publishes_refused./particle/pose', value=str(refused))] if refused else [])])])
        writer.add_topic('/diagnostics', type_name(diag))
        writer.write('/diagnostics', serialize_message(diag), t + 3)
    received = n + trajectories + receipts + (diag_commands is not None)
    writer.custom_data.update({'received_total': str(received), 'lost_total': str(lost),
                               'incompatible_qos_total': '0', 'lost./actuator/trajectory': str(lost)})
    writer.close()
