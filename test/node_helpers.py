"""Helpers for the actuator/simulator node tests: an outside listener on every topic, service calls and
stepping with bounded waits (on top of ros_helpers: context fixture, wait_until)."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from ros_helpers import wait_until
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory

from micro_feeder.interface.topics import TOPICS
from micro_feeder.nodes._ros import message_class, topic_qos


def _deep(topic: str) -> QoSProfile:
    """The topic's QoS with a deep history, so that nothing is overwritten between two spins."""
    qos = topic_qos(topic)
    qos.depth = 1000
    return qos


class Probe(Node):
    """An outside client: subscribes to every topic of the contract with its QoS and keeps what arrives."""

    def __init__(self, **kwargs: Any):
        super().__init__('probe', **kwargs)
        self.msgs: dict[str, list] = defaultdict(list)
        for spec in TOPICS:
            self.create_subscription(message_class(spec.type), spec.name,
                                     lambda msg, name=spec.name: self.msgs[name].append(msg), _deep(spec.name))
        self.publishers_ = {name: self.create_publisher(msg_type, name, topic_qos(name)) for name, msg_type in
                            (('actuator/trajectory', JointTrajectory), ('actuator/command', Float64MultiArray))}

    def publish(self, topic: str, msg: Any, executor: Executor) -> None:
        """Publish once a subscriber is matched (so nothing is lost to discovery)."""
        pub = self.publishers_[topic]
        wait_until(lambda: pub.get_subscription_count() > 0, 10.0, executor=executor, what=f'{topic} subscriber')
        pub.publish(msg)

    def call(self, executor: Executor, srv_type: type, name: str, request: Any = None, timeout: float = 10.0) -> Any:
        """Call a service and return its response (bounded wait)."""
        client = self.create_client(srv_type, name)
        wait_until(client.service_is_ready, timeout, executor=executor, what=f'service {name}')
        future = client.call_async(request if request is not None else srv_type.Request())
        wait_until(future.done, timeout, executor=executor, what=f'response of {name}')
        self.destroy_client(client)
        return future.result()

    def step(self, executor: Executor, n: int = 1) -> None:
        """``simulator/step`` n times, each waiting for the pose it publishes."""
        for _ in range(n):
            count = len(self.msgs['particle/pose'])
            response = self.call(executor, Trigger, 'simulator/step')
            assert response.success, response.message
            wait_until(lambda c=count: len(self.msgs['particle/pose']) > c, 10.0, executor=executor,
                       what='pose after a step')

    def pause(self, executor: Executor, paused: bool) -> SetBool.Response:
        return self.call(executor, SetBool, 'simulator/pause', SetBool.Request(data=paused))


def stamp_s(msg: Any) -> float:
    """A header stamp (or a Clock's clock) in seconds."""
    t = msg.clock if hasattr(msg, 'clock') else msg.header.stamp
    return t.sec + t.nanosec * 1e-9


def start_process(name: str, *ros_args: str) -> subprocess.Popen:
    """Start the installed console script ``name`` with ``--ros-args ros_args`` (output captured)."""
    exe = shutil.which(name, path=str(Path(sys.executable).parent))
    assert exe, f'console script {name!r} not installed (pip install -e .)'
    return subprocess.Popen([exe, '--ros-args', *ros_args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def proc_status(pid: int, key: str) -> str | None:
    """The first field of ``key`` (VmRSS, VmHWM in kB; SigCgt in hex ...) in /proc/PID/status, as written
    there; None when the process has gone."""
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith(key + ':'):
                return line.split()[1]
    except OSError:
        return None
    return None


def stop_process(proc: subprocess.Popen) -> tuple[int, str]:
    """SIGINT and wait (SIGKILL after 20 s, after SIGUSR1 for its threads' stacks): (exit status, -9 when
    killed; output). Stopping it again gives the same answer (its output is read once)."""
    stopped = getattr(proc, 'stopped', None)
    if stopped is not None:
        return stopped
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=20)
        proc.stopped = (proc.returncode, out)
    except subprocess.TimeoutExpired:         # stuck: its threads' stacks (SIGUSR1, StopFlag) go with its output
        proc.send_signal(signal.SIGUSR1)
        time.sleep(1.0)
        proc.kill()
        out, _ = proc.communicate()
        proc.stopped = (-9, out)
    return proc.stopped
