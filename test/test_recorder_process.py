"""The real ``recorder`` executable: SIGKILL loses at most ``flush_period`` of what was published;
SIGTERM and SIGINT leave a complete log with every message."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
import rclpy
from geometry_msgs.msg import PoseStamped
from log_fixtures import pose
from rclpy._rclpy_pybind11 import RCLError
from rclpy.duration import Duration
from ros_helpers import remove_stale_fastdds_shm, wait_until

from micro_feeder.logs.reader import LogReader, TruncatedLogWarning

FLUSH_PERIOD = 0.5  # s
RATE = 500.0  # Hz
DELIVERY_MARGIN = 0.05  # s: receive latency and scheduling between publish and the recorder's write


def start_recorder(output, flush_period=FLUSH_PERIOD) -> subprocess.Popen:
    exe = shutil.which('recorder', path=str(Path(sys.executable).parent)) or shutil.which('recorder')
    assert exe, 'console script "recorder" not installed (pip install -e .)'
    return subprocess.Popen([exe, '--ros-args', '-p', f'output:={output}', '-p', f'flush_period:={flush_period}'],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def publish_for(publisher, seconds: float, first: int = 0) -> list[float]:
    """Publish poses ``first``, ``first`` + 1, ... at RATE for ``seconds``; returns each one's publish time
    (monotonic). A pose the middleware refuses to take (``RCLError``: Fast DDS could not make room in the
    writer's history within its max_blocking_time, seen once when a stopped recorder resumed on a loaded
    machine) was not published: its index goes to the next pose, and the time it took is spent."""
    times: list[float] = []
    start = time.monotonic()
    while (now := time.monotonic()) - start < seconds:
        while len(times) < (now - start) * RATE:
            try:
                publisher.publish(pose(first + len(times)))
            except RCLError:
                print('a pose refused by the middleware')
                break
            times.append(time.monotonic())
        time.sleep(0.0005)
    return times


@pytest.fixture
def pose_publisher(ros_context):
    node = rclpy.create_node('publisher', context=ros_context)
    yield node.create_publisher(PoseStamped, 'particle/pose', 100)
    node.destroy_node()


WARM_UP = -1   # index of the pose that connects publisher and recorder before the counted ones


def connect(publisher) -> None:
    """Publish the warm-up pose and wait until the recorder has acknowledged it: its reader is then matched,
    so no counted pose is lost to discovery (a publisher-side subscription count of 1 was not enough: the
    first 30-105 poses were sometimes missing)."""
    wait_until(lambda: publisher.get_subscription_count() == 1, 20, what='recorder subscribed')
    warm_up = pose(0)
    warm_up.pose.position.x = WARM_UP * 1e-6
    publisher.publish(warm_up)
    assert publisher.wait_for_all_acked(Duration(seconds=20)), 'the recorder never acknowledged the warm-up pose'


def recorded_indices(log: LogReader) -> list[int]:
    """Indices of the counted poses in the log, after checking that the warm-up pose came first."""
    indices = [round(m.message.pose.position.x * 1e6) for m in log.messages(['particle/pose'])]
    assert indices[:1] == [WARM_UP], 'the warm-up pose must be the first one recorded'
    return indices[1:]


def test_sigkill_loses_at_most_flush_period(tmp_path, pose_publisher):
    proc = start_recorder(tmp_path / 'log')
    try:
        connect(pose_publisher)
        times = publish_for(pose_publisher, 2.2)
        killed_at = time.monotonic()
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(10)
        remove_stale_fastdds_shm()
    with pytest.warns(TruncatedLogWarning):
        log = LogReader(tmp_path / 'log')
    got = recorded_indices(log)
    assert got == list(range(len(got))), 'the log must hold a gap-free prefix of what was published'
    last_saved_at = times[got[-1]]
    lost_window = killed_at - last_saved_at
    print(f'SIGKILL: {len(times)} published, {len(got)} on disk, lost the last {lost_window:.3f} s '
          f'(flush_period {FLUSH_PERIOD} s)')
    assert lost_window <= FLUSH_PERIOD + DELIVERY_MARGIN


@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGINT])
def test_sigterm_and_sigint_leave_a_complete_log(tmp_path, pose_publisher, sig):
    proc = start_recorder(tmp_path / 'log')
    try:
        connect(pose_publisher)
        times = publish_for(pose_publisher, 1.0)
        time.sleep(0.2)  # let the last messages travel before the stop signal: loss would not be the recorder's
        proc.send_signal(sig)
        output, _ = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, output
    assert 'particle/pose' in output  # the summary printed on exit
    with warnings.catch_warnings():
        warnings.simplefilter('error', TruncatedLogWarning)
        log = LogReader(tmp_path / 'log')
    assert (tmp_path / 'log' / 'metadata.yaml').is_file()
    assert recorded_indices(log) == list(range(len(times)))
    assert log.recorder_info['lost_total'] == '0'


def test_messages_missed_while_the_recorder_was_stopped_are_counted_lost(tmp_path, pose_publisher):
    """Stopped (SIGSTOP) for longer than the transport can queue, the recorder misses poses: the middleware's
    sample-lost count, read by the recorder once a second and at the stop, says how many (the log's
    ``lost_total``), and what was recorded plus what was counted lost is what was published."""
    proc = start_recorder(tmp_path / 'log')
    try:
        connect(pose_publisher)
        times = publish_for(pose_publisher, 0.3)
        proc.send_signal(signal.SIGSTOP)
        try:
            times += publish_for(pose_publisher, 3.0, len(times))
        finally:
            proc.send_signal(signal.SIGCONT)
        times += publish_for(pose_publisher, 1.5, len(times))
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, output
    log = LogReader(tmp_path / 'log')
    got = recorded_indices(log)
    lost = int(log.recorder_info['lost./particle/pose'])
    print(f'SIGSTOP 3 s: {len(times)} published, {len(got)} recorded, {lost} counted lost')
    assert len(got) < len(times), 'the stop was meant to overflow the transport'
    assert len(got) + lost == len(times)
