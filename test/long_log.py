"""A long log like ``micro-feeder run --set stroke.count=0 --record`` writes, made offline in a fraction of the
time: the simulator's Stepper in 1 ms steps (``real_time_factor`` 0: the stops are sums of ``step_period``,
so ``resim`` rebuilds them exactly), driven by the actuator's own streamed windows (``stream.window`` 20 ms,
``stream.lead`` 0.2 s), each received (and acknowledged on ``simulator/command_receipts``) at the step the
actuator would send it. Every step writes what the simulator publishes at 1 kHz (pose, twist, contact
wrench, joint states, clock, with the node's own serializers), mode changes go to ``particle/contact_state``
and ``particle/transitions``, the surface markers at 25 Hz and a ``/diagnostics`` message every second.

``resim`` of such a log is IDENTICAL (bit for bit). :func:`measure` runs a log command on it in a new process
and watches its memory, progress lines and Ctrl-C: what ``test_long_logs.py`` and ``bench/bench_long_logs.py``
use. Command line: ``python test/long_log.py OUT --minutes 10``.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from node_helpers import proc_status
from rcl_interfaces.msg import ParameterEvent
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message

from micro_feeder.interface import messages, stamps
from micro_feeder.interface.names import joint_names, receipt_frame
from micro_feeder.interface.transitions import TransitionEncoder
from micro_feeder.logs.writer import LogWriter
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.settings import model_specs
from micro_feeder.sim.commands import parse_trajectory_cdr
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import StrokeStream, encode_window

STEP = 1e-3                 # s: the simulator's default step_period
LEAD, WINDOW = 0.2, 0.02    # s: the actuator's default stream.lead and stream.window
MAX_POINTS = 2000           # the actuator's default stream.max_points
LOG_T0 = 1_700_000_000_000_000_000   # ns: receive time of sim time 0
TOPICS = {
    '/particle/pose': 'geometry_msgs/msg/PoseStamped',
    '/particle/twist': 'geometry_msgs/msg/TwistStamped',
    '/particle/contact_wrench': 'geometry_msgs/msg/WrenchStamped',
    '/actuator/joint_states': 'sensor_msgs/msg/JointState',
    '/clock': 'rosgraph_msgs/msg/Clock',
    '/particle/contact_state': 'std_msgs/msg/String',
    '/particle/transitions': 'diagnostic_msgs/msg/DiagnosticArray',
    '/surface/markers': 'visualization_msgs/msg/MarkerArray',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    '/actuator/trajectory': 'trajectory_msgs/msg/JointTrajectory',
    '/simulator/command_receipts': 'std_msgs/msg/Header',
    '/simulator/parameters': 'rcl_interfaces/msg/ParameterEvent',
}


def parameters_event(flat: dict) -> bytes:
    """``simulator/parameters`` as the simulator publishes it at t = 0 (its model and node parameters)."""
    node = {'real_time_factor': 0.0, 'step_period': STEP, 'start_paused': False, 'lockstep': False}
    params = [Parameter(name, value=value).to_parameter_msg() for name, value in {**flat, **node}.items()]
    return serialize_message(ParameterEvent(stamp=stamps.to_time(0.0), node='/simulator', new_parameters=params))


def recorder_counters(received: int) -> dict[str, str]:
    """The recorder's counters (its ``/diagnostics`` status and, on a clean stop, the log's metadata record)."""
    return {'received_total': str(received), 'lost_total': '0', 'incompatible_qos_total': '0'}


def diagnostics(t: float, published: int, received: int) -> bytes:
    """The simulator's loop status and the recorder's, as each publishes them once a second."""
    loop = DiagnosticStatus(name='simulator: loop', values=[KeyValue(key='real_time_factor_achieved', value='1.0'),
                                                             KeyValue(key='states_published', value=str(published))])
    recorder = DiagnosticStatus(name='recorder: log', values=[KeyValue(key=k, value=v)
                                                              for k, v in recorder_counters(received).items()])
    msg = DiagnosticArray(status=[loop, recorder])
    msg.header.stamp = stamps.to_time(t)
    return serialize_message(msg)


def write_long_log(path: Path | str, seconds: float, *, markers: bool = True, progress: bool = False) -> dict:
    """Write ``seconds`` of sim time (1 kHz steps) of continuous strokes to ``path``; returns counts."""
    flat = {name: default for name, (_, default) in model_specs().items()}
    stepper = Stepper(build_model(flat))
    n = stepper.model.n_actuators
    names = joint_names(n)
    params = StrokeParams.from_flat(flat)
    stream = StrokeStream(params, 0, n, 0, window=WINDOW, max_points=MAX_POINTS, knots_per_stroke=0)
    state = messages.StateMessages(names)
    transitions = TransitionEncoder('simulator')
    surface = stepper.model.surface
    c, w = np.asarray(surface.centers), np.asarray(surface.widths)
    surface_markers = messages.SurfaceMarkers(np.linspace(float(np.min(c - 4 * w)), float(np.max(c + 4 * w)), 200),
                                              surface.centers, surface.widths, 20e-6)
    writer = LogWriter(path)
    for topic, type_name in TOPICS.items():
        writer.add_topic(topic, type_name)
    counts = {'poses': 0, 'windows': 0, 'transitions': 0}
    mode = None
    steps = round(seconds / STEP)
    started = time.monotonic()

    def log_ns(i: int, k: int = 0) -> int:        # receive time: step i's messages, k ns apart
        return LOG_T0 + i * 1_000_000 + k

    writer.write('/simulator/parameters', parameters_event(flat), log_ns(0))
    events: list = []
    for i in range(steps + 1):
        if i:
            events = stepper.advance(stepper.t + STEP)
        obs = stepper.observe()
        state.update(obs, obs.stroke_velocities)
        k = 0
        for topic, data in (('/particle/pose', state.pose), ('/particle/twist', state.twist),
                            ('/particle/contact_wrench', state.wrench), ('/actuator/joint_states', state.joints)):
            writer.write(topic, data, log_ns(i, k := k + 1))
        modes = []                          # as the simulator publishes: each event, then the step's mode
        for event in events:
            if event.kind != 'reversal':
                writer.write('/particle/transitions', transitions.encode(event), log_ns(i, k := k + 1))
                counts['transitions'] += 1
                modes.append(event.to_mode)
        for new in (*modes, obs.mode):
            if new != mode:
                mode = new
                writer.write('/particle/contact_state', messages.contact_state_bytes(mode), log_ns(i, k := k + 1))
        writer.write('/clock', state.clock, log_ns(i, k := k + 1))
        if markers and not i % 40:
            writer.write('/surface/markers', surface_markers.update(obs, state.stamp), log_ns(i, k := k + 1))
        if i and not i % 1000:
            writer.write('/diagnostics', diagnostics(stepper.t, i, writer.message_count), log_ns(i, k := k + 1))
        counts['poses'] += 1
        # the actuator hears this step's joint state and keeps LEAD of strokes ahead; the simulator receives
        # each window before its next step (receipt = this step's sim time)
        while stream.scheduled_until < stepper.t + LEAD:
            command_id = f'/actuator@long_log:b1:w{counts["windows"] + 1}'
            data = encode_window(stream.next_window(), command_id)
            writer.write('/actuator/trajectory', data, log_ns(i, k := k + 1))
            stepper.command_trajectory(parse_trajectory_cdr(data, names, stepper.limits))
            writer.write('/simulator/command_receipts',
                         messages.header_bytes(stepper.t, receipt_frame('actuator/trajectory', command_id)),
                         log_ns(i, k := k + 1))
            counts['windows'] += 1
        if progress and not i % 10_000:
            print(f'\r  {i * STEP:7.1f} of {seconds:g} s sim time, {time.monotonic() - started:5.0f} s', end='',
                  file=sys.stderr, flush=True)
    writer.custom_data.update(recorder_counters(writer.message_count))
    writer.close()
    if progress:
        print(file=sys.stderr)
    return counts


# -- running a log command on it, watched -----------------------------------------------------------------
# The command as the program runs it (main() reads sys.argv), then its own peak RSS on stderr at exit (VmHWM:
# what sampling might miss between two samples; not ru_maxrss, which on Linux keeps the forking parent's size
# across exec). An exit handler: it runs on Ctrl-C too, where the program ends without the interpreter's teardown.
WRAPPER = ('import atexit, sys\n'
           'def peak():\n'
           '    hwm = [line.split()[1] for line in open("/proc/self/status") if line.startswith("VmHWM:")]\n'
           '    print(f"maxrss_kb {hwm[0]}", file=sys.stderr, flush=True)\n'
           'atexit.register(peak)\n'
           'sys.argv[0] = "micro-feeder"\n'
           'from micro_feeder.cli import main\n'
           'sys.exit(main())\n')


def status_kb(pid: int, key: str) -> int | None:
    """``key`` (VmRSS, VmHWM ...) of a process from /proc, in kB; None when it is gone."""
    value = proc_status(pid, key)
    return None if value is None else int(value)


def is_progress(line: str) -> bool:
    """A line of :class:`micro_feeder.progress.Progress`."""
    return '% (' in line and 'Ctrl-C stops' in line


def measure(args: list[str], *, rss_cap_mb: float = 1e9, timeout: float = 3600.0, sigint_after: float | None = None,
            sigint_on: Callable[[str], bool] | None = None) -> dict:
    """Run ``micro-feeder ARGS`` in a new process and watch it: its peak RSS (killed above ``rss_cap_mb``
    MB, or after ``timeout`` s), wall time, when its first progress line came; SIGINT (Ctrl-C) sent
    ``sigint_after`` s into the run or when a stderr line satisfies ``sigint_on``, and how long it then
    took to exit."""
    proc = subprocess.Popen([sys.executable, '-c', WRAPPER, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, 'PYTHONUNBUFFERED': '1'})
    start = time.monotonic()
    lines: list[tuple[float, str]] = []
    out: list[str] = []
    readers = [threading.Thread(target=lambda: lines.extend((time.monotonic() - start, line.rstrip('\n'))
                                                            for line in proc.stderr), daemon=True),
               threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True)]
    for reader in readers:
        reader.start()
    peak_kb, killed, sigint_at = 0, '', None
    while proc.poll() is None:
        now = time.monotonic() - start
        peak_kb = max(peak_kb, status_kb(proc.pid, 'VmHWM') or 0)
        if peak_kb > rss_cap_mb * 1024:
            killed = f'killed at {peak_kb / 1024:.0f} MB RSS after {now:.0f} s'
        elif now > timeout:
            killed = f'killed after {now:.0f} s (timeout)'
        if killed:
            proc.kill()
            break
        due = (sigint_after is not None and now >= sigint_after) or (
            sigint_on is not None and any(sigint_on(line) for _, line in list(lines)))
        if due:
            proc.send_signal(signal.SIGINT)
            sigint_at = time.monotonic()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                killed = 'killed: still running 30 s after SIGINT'
            break
        time.sleep(0.05)
    proc.wait()
    end = time.monotonic()
    for reader in readers:
        reader.join(timeout=5)
    text = [line for _, line in lines]
    maxrss = next((int(line.split()[1]) for line in text if line.startswith('maxrss_kb ')), None)
    return {'args': args, 'wall_s': end - start, 'status': proc.returncode, 'killed': killed,
            'peak_mb': max(peak_kb, maxrss or 0) / 1024,
            'first_progress_s': next((t for t, line in lines if is_progress(line)), None),
            'sigint_to_exit_s': None if sigint_at is None else end - sigint_at,
            'stdout': ''.join(out), 'stderr': [line for line in text if not line.startswith('maxrss_kb ')]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('out', help='new log directory (or a .mcap file name)')
    parser.add_argument('--minutes', type=float, default=10.0, help='sim time to write (default 10)')
    parser.add_argument('--no-markers', action='store_true', help='leave out surface/markers')
    args = parser.parse_args()
    started = time.monotonic()
    counts = write_long_log(args.out, args.minutes * 60.0, markers=not args.no_markers, progress=True)
    print(f'{args.out}: {counts} in {time.monotonic() - started:.0f} s')


if __name__ == '__main__':
    main()
