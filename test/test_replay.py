"""The replay node: reproduces the recorded message sequence byte for byte at the recorded timing,
measures its timing error, honours topic filter, remap and pause."""

from __future__ import annotations

import time

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from log_fixtures import write_motion_log
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_helpers import wait_until
from std_srvs.srv import SetBool

from micro_feeder.nodes.replay import Replay

N = 300  # messages per topic, 1 ms apart: 0.3 s of log


def run_replay(context, log_path, overrides, topic='/particle/pose', pause_for=0.0, expect=N):
    listener = rclpy.create_node('listener', context=context)
    got: list[tuple[float, bytes]] = []
    listener.create_subscription(PoseStamped, topic, lambda data: got.append((time.monotonic(), data)), 1000,
                                 raw=True)
    replay = Replay(context=context, parameter_overrides=[Parameter('log', value=str(log_path)), *overrides])
    pause = listener.create_client(SetBool, 'replay/pause')
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(replay)
    executor.add_node(listener)
    try:
        wait_until(lambda: listener.count_publishers(topic) == 1 and pause.service_is_ready(), 10,
                   executor=executor, what='replay publisher matched')
        replay.start()
        if pause_for:
            wait_until(lambda: replay.published > 50, 5, executor=executor, what='replay started')
            f = pause.call_async(SetBool.Request(data=True))
            wait_until(f.done, 5, executor=executor, what='paused')
            held = replay.published
            deadline = time.monotonic() + pause_for
            wait_until(lambda: time.monotonic() > deadline, pause_for + 1, executor=executor)
            assert replay.published <= held + 1  # at most the one already due when the pause came
            f = pause.call_async(SetBool.Request(data=False))
            wait_until(f.done, 5, executor=executor, what='resumed')
        wait_until(replay.finished.done, 10, executor=executor, what='replay finished')
        wait_until(lambda: len(got) >= expect, 5, executor=executor, what='messages delivered')
    finally:
        replay.close()
        executor.shutdown()
        replay.destroy_node()
        listener.destroy_node()
    return replay, got


def test_replay_reproduces_sequence_and_timing(ros_context, tmp_path):
    poses = write_motion_log(tmp_path / 'log', n=N)
    replay, got = run_replay(ros_context, tmp_path / 'log', [])
    assert [data for _, data in got] == poses
    errors = np.asarray(replay.timing_errors)
    assert len(errors) == 3 * N + 3  # pose, twist, wrench N each, contact_state 3
    p99 = np.percentile(errors, 99)
    print(f'replay timing error p50 {np.percentile(errors, 50) * 1e3:.3f} ms, p99 {p99 * 1e3:.3f} ms')
    assert p99 < 0.025  # in-process: the listener competes for the GIL (measured 4-12 ms)
    arrival = np.asarray([t for t, _ in got])
    assert abs((arrival[-1] - arrival[0]) - (N - 1) * 1e-3) < 0.02  # recorded span 0.299 s


def test_filter_remap_rate_and_pause(ros_context, tmp_path):
    poses = write_motion_log(tmp_path / 'log', n=N)
    replay, got = run_replay(ros_context, tmp_path / 'log', [
        Parameter('topics', value=['particle/pose']), Parameter('remap', value=['/particle/pose:=/copy']),
        Parameter('rate', value=2.0)], topic='/copy', pause_for=0.3)
    assert replay.topics == ['/particle/pose']
    assert [data for _, data in got] == poses
    arrival = np.asarray([t for t, _ in got])
    assert arrival[-1] - arrival[0] > 0.3  # the pause held playback
    assert np.percentile(replay.timing_errors, 99) < 0.025
