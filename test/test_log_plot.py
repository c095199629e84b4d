"""The log plot: strokes rebuilt from the recorded commands (not the 1 kHz samples), the default window
around what happens, and ``--start/--end``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import Parameter, ParameterEvent, ParameterType, ParameterValue
from rclpy.serialization import serialize_message
from std_msgs.msg import Header, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from micro_feeder.cli import main as cli_main
from micro_feeder.logs.reader import LogReader
from micro_feeder.logs.series import part_series
from micro_feeder.logs.strokes import commanded_strokes
from micro_feeder.logs.writer import LogWriter
from micro_feeder.plots.log import active_window, plot_log

T0 = 1_700_000_000_000_000_000  # ns, receive-time origin
RECEIVED = 0.5                  # s, sim time at which the simulator received the trajectory
KNOTS = (0.0, 0.5e-3, 1.0e-3)   # s from receipt
PEAK = 100e-6                   # m


def ns(t: float) -> int:
    return round(t * 1e9)


def write_log(path: Path) -> None:
    """2 s of poses at 1 kHz; one trajectory (two actuators, listed in reverse order) received at 0.5 s;
    the part slides from 0.5003 to 0.5012 s."""
    writer = LogWriter(path)
    for topic, type_ in (('/particle/pose', 'geometry_msgs/msg/PoseStamped'),
                         ('/particle/contact_state', 'std_msgs/msg/String'),
                         ('/actuator/trajectory', 'trajectory_msgs/msg/JointTrajectory'),
                         ('/simulator/command_receipts', 'std_msgs/msg/Header'),
                         ('/simulator/parameters', 'rcl_interfaces/msg/ParameterEvent')):
        writer.add_topic(topic, type_)
    def array(values: list[float]) -> ParameterValue:
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE_ARRAY, double_array_value=values)

    params = ParameterEvent(new_parameters=[Parameter(name='surface.centers', value=array([0.0, 2e-3])),
                                            Parameter(name='surface.widths', value=array([1e-3, 1e-3]))])
    writer.write('/simulator/parameters', serialize_message(params), T0)
    writer.write('/particle/contact_state', serialize_message(String(data='stuck')), T0)
    for i in range(2001):
        t = i * 1e-3
        msg = PoseStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns(t), 1_000_000_000)
        msg.pose.position.x = 5e-4 - 2e-6 * min(max(t - 0.5003, 0.0) / 0.0009, 1.0)
        writer.write('/particle/pose', serialize_message(msg), T0 + ns(t) + 1000)
        if i == 500:
            traj = JointTrajectory(joint_names=['piezo_1', 'piezo_0'], points=[
                JointTrajectoryPoint(positions=[0.0, p], velocities=[0.0, 0.0]) for p in (0.0, PEAK, 0.0)])
            for point, offset in zip(traj.points, KNOTS, strict=True):
                point.time_from_start.nanosec = ns(offset)
            writer.write('/actuator/trajectory', serialize_message(traj), T0 + ns(t) + 2000)
            receipt = Header(frame_id='actuator/trajectory')
            receipt.stamp.sec, receipt.stamp.nanosec = divmod(ns(RECEIVED), 1_000_000_000)
            writer.write('/simulator/command_receipts', serialize_message(receipt), T0 + ns(t) + 3000)
    for t, mode in ((0.5003, 'sliding'), (0.5012, 'stuck')):
        writer.write('/particle/contact_state', serialize_message(String(data=mode)), T0 + ns(t) + 500)
    writer.close()


@pytest.fixture(scope='module')
def log_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('logplot') / 'run'
    write_log(path)
    return path


def test_strokes_come_from_the_commands_at_their_receipt(log_path: Path) -> None:
    log = LogReader(log_path)
    s = part_series(log)
    strokes = commanded_strokes(log, 2, s.pose.log_t, s.pose.t)
    assert strokes is not None
    at = strokes.at(np.array([0.4, RECEIVED, RECEIVED + KNOTS[1], RECEIVED + 0.25e-3, 0.9]))
    assert at[:, 1] == pytest.approx([0.0, 0.0, 0.0, 0.0, 0.0], abs=1e-18)      # piezo_1 commanded 0
    # piezo_0: the knots, and the cubic Hermite between them (zero velocities: half way = half the peak)
    assert at[:, 0] == pytest.approx([0.0, 0.0, PEAK, PEAK / 2, 0.0], abs=1e-15)
    assert strokes.active == [(RECEIVED, pytest.approx(RECEIVED + KNOTS[-1]))]


def test_the_default_window_frames_what_happens(log_path: Path) -> None:
    log = LogReader(log_path)
    s = part_series(log)
    strokes = commanded_strokes(log, 2, s.pose.log_t, s.pose.t)
    lo, hi = active_window(s, strokes, 0.0, 2.0)
    assert lo < RECEIVED and hi > 0.5012            # the command and the slide
    assert hi - lo < 0.01                           # not the whole 2 s


def test_plot_command_with_a_window_and_a_refused_one(log_path: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(['plot', str(log_path), '-o', str(tmp_path / 'a.png')]) == 0
    assert cli_main(['plot', str(log_path), '-o', str(tmp_path / 'b.png'), '--start', '0.4', '--end', '0.6']) == 0
    for name in ('a.png', 'b.png'):
        assert (tmp_path / name).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert cli_main(['plot', str(log_path), '-o', str(tmp_path / 'c.png'), '--start', '1', '--end', '0.5']) == 2
    assert 'empty time window: start 1 s, end 0.5 s' in capsys.readouterr().err
    assert not (tmp_path / 'c.png').exists()
    assert plot_log(LogReader(log_path), tmp_path / 'd.png', start=0.49, end=0.51).stat().st_size > 10_000
