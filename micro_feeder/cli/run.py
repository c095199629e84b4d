"""``micro-feeder run``: the actuator and the simulator (and optionally the recorder) in one process.

ROS traffic stays on this host unless ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is already set. The nodes share
one EventsExecutor on the main thread; a live status line goes to stderr (when it is a terminal) and a
summary to stdout at the end. Ctrl-C (or SIGTERM) ends the run cleanly, the log included. A recording that
fails (disk full, log directory removed, storage not responding) stops with one error line and the run
goes on; its summary says where the log ends and why, and the exit status is then 1.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any, TextIO

from . import CommandError
from ._common import add_model_options, settings_from_args
from ._foxglove import add_foxglove_option, live_view
from ._session import READY_TIMEOUT, add_namespace_option, namespace, ros_session, validate

STATUS_PERIOD = 0.2   # s (wall clock) between two status line updates
READY_POLL = 0.002    # s (wall clock) between two checks of what the run waits for at t = 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'run', help='run the actuator and simulator nodes (and a recorder) in one process',
        description='Run the actuator and simulator ROS 2 nodes in one process: the actuator sends the '
                    'stroke burst of the stroke.* parameters, the simulator publishes the part\'s state '
                    '(docs/interface.md). Ends after --duration sim seconds or on Ctrl-C.')
    add_model_options(parser)
    parser.add_argument('--duration', type=float, metavar='SECONDS',
                        help='sim time to run (s); default: until Ctrl-C')
    parser.add_argument('--real-time-factor', type=float, default=1.0, metavar='RTF',
                        help='sim seconds per wall second, 0 = as fast as possible (default 1)')
    parser.add_argument('--record', metavar='PATH',
                        help='record every topic to this log (rosbag2 directory with MCAP, see docs/logs.md)')
    add_foxglove_option(parser)
    add_namespace_option(parser)
    parser.set_defaults(func=run)


def status_line(sim: Any) -> str:
    """``sim 0.123456 s  running  stuck  x = +0.497393 mm  RTF 1.00`` (RTF: last second)."""
    state = sim.stepper.state
    run_mode = 'error' if sim.error else ('paused' if sim.paused else 'running')
    return (f'sim {state.t:10.6f} s  {run_mode:7s}  {state.mode:7s}  x = {state.x * 1e3:+.6f} mm  '
            f'RTF {sim.achieved_rtf:.2f}')


def summary(sim: Any, actuator: Any, wall_s: float, log: str | None, fate: str = '') -> str:
    """What the run did, for stdout; ``fate``: how the recording ended when it stopped early."""
    state = sim.stepper.state
    lines = [f'sim time        {state.t:.6f} s in {wall_s:.2f} s wall (real-time factor {state.t / wall_s:.3f})',
             f'part            {state.mode} at x = {state.x * 1e3:.6f} mm, moved {state.distance * 1e6:+.3f} um, '
             f'max speed {state.max_speed * 1e3:.3f} mm/s',
             'transitions     ' + ', '.join(f'{k} {v}' for k, v in state.transitions.items()),
             f'commands        {actuator.bursts} bursts sent, {sim.rejected} rejected, {sim.commands.late} late; '
             f'{sim.overruns} loop overruns']
    parts = sim.stepper.parts_state
    if len(parts.parts) > 1:
        lines[1] = f'part 0          {lines[1].removeprefix("part").lstrip()}'
        lines[3:3] = [f'part {k:<10d} {p.mode} at x = {p.x * 1e3:.6f} mm, moved {p.distance * 1e6:+.3f} um, '
                      f'transitions {", ".join(str(v) for v in p.transitions.values())}'
                      for k, p in enumerate(parts.parts[1:], start=1)]
        lines.insert(3 + len(parts.parts) - 1, f'impacts         {parts.collisions} between parts')
    if sim.error:
        lines.append(f'error           {sim.error}')
    if log:
        lines.append(f'log             {log}' + (f': {fate}' if fate else ''))
    return '\n'.join(lines)


def _wait_until_ready(session: Any, sim: Any, actuator: Any) -> None:
    """Spin (sim time held at 0) until the simulator hears the actuator, the recorder (if any) hears every
    simulator topic and the actuator's command, and the burst (or a streamed burst's first window, which
    starts at the held time: strokes from t = 0 as offline) has reached the simulator; at most
    :data:`READY_TIMEOUT` s of wall time, then start anyway and say what is missing. The actuator (built
    without ``auto_start``) sends its burst here, once every subscriber is matched: its own auto-start sends
    it when the simulator alone is, and it polled only every 50 ms. Matched means on both ends: the actuator's
    publisher counted the simulator's subscription before that subscription knew the publisher, and the
    burst sent then was lost (the run waited 10 s and started without it, on a loaded machine)."""
    from rclpy.clock import Clock, ClockType
    from rclpy.task import Future

    recording = session.recorder is not None

    def listening() -> list[str]:
        out = []
        if actuator.trajectory_subscribers() < 1 + recording or not sim.hears('actuator/trajectory'):
            out.append('the simulator' + (' and the recorder' if recording else '') + ' on actuator/trajectory')
        if not session.recorder_hears(sim):
            out.append('the recorder on the simulator\'s topics')
        return out

    def missing() -> list[str]:
        out = listening()
        if sim.commands.received < 1:
            out.append('the actuator\'s burst at the simulator')
        return out

    from ..nodes.actuator import NotSent

    deadline = time.monotonic() + READY_TIMEOUT
    ready = Future()
    started = []

    def start() -> None:
        if not started:
            try:
                actuator.get_logger().info(actuator.start(held_at=sim.stepper.t))
            except NotSent as err:      # refused: the next check sends it again
                actuator.get_logger().warning(f'{err}: sending it again')
                return
            started.append(True)

    # checked by a timer that ends the spin at once (the spin's own checks come every 0.1 s: that held the run
    # at t = 0, and its log after the first pose, up to 100 ms longer than needed)
    def check() -> None:
        if not listening():
            start()
        if not ready.done() and (not missing() or time.monotonic() > deadline):
            ready.set_result(True)

    timer = sim.create_timer(READY_POLL, check, clock=Clock(clock_type=ClockType.STEADY_TIME))
    session.spin(ready.done, ready)
    sim.destroy_timer(timer)
    if missing() and not session.stop:
        print(f'micro-feeder run: started after {READY_TIMEOUT:g} s without {"; ".join(missing())}',
              file=sys.stderr)
    if not session.stop:
        start()


def run(args: argparse.Namespace) -> int:
    flat = settings_from_args(args)
    if args.duration is not None and not args.duration > 0:
        raise CommandError('--duration must be > 0')
    ns = namespace(args.namespace)
    # stroke.count 0 (strokes until stopped, streamed) is the actuator's; the model's count is at least 1
    # and unused by the simulator, whose strokes are the actuator's commands
    model_flat = {name: value for name, value in flat.items() if not (name == 'stroke.count' and value == 0)}
    validate(model_flat)      # before the recorder creates the log
    with live_view(args.foxglove) as viewer, ros_session(args.record, ns, viewer) as session:
        from ..nodes.actuator import Actuator
        from ..nodes.simulator import Simulator

        # paused until the actuator's burst and the recorder are there: the run (and its log) starts at t = 0
        sim = session.add(lambda: Simulator(context=session.context, namespace=ns,
                                            overrides={**model_flat, 'real_time_factor': args.real_time_factor,
                                                       'publish_thread': False},     # one process, one GIL
                                            hold=True))
        end = sim.stop_at(args.duration) if args.duration is not None else None   # before the actuator is built
        actuator = session.add(lambda: Actuator(context=session.context, namespace=ns,
                                                overrides={**flat, 'auto_start': False}))   # started when ready
        _wait_until_ready(session, sim, actuator)
        sim.resume()
        tty: TextIO | None = sys.stderr if sys.stderr.isatty() else None
        if tty is not None:
            sim.create_timer(STATUS_PERIOD, lambda: print('\r' + status_line(sim), end='', file=tty, flush=True))
        start = time.perf_counter()
        session.spin(lambda: bool(sim.error), end)
        wall = time.perf_counter() - start
        sim.pause()     # the loop thread no longer advances the state the summary reads
        if tty is not None:
            print('\r' + status_line(sim), file=tty)
        log = session.close_log()
        fate = session.recording_fate()
        print(summary(sim, actuator, wall, log, fate))
        return 1 if sim.error or fate else 0
