"""``micro-feeder hil``: the simulator with the example feed controller in the loop, in one process.

Real-time mode: the simulator runs on the wall clock and the controller reacts as fast as it can.
Lockstep mode (``--lockstep``): the simulator advances only when the controller grants a step, so the
physics is the same however slow the controller is (docs/hil.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from . import CommandError
from ._common import add_model_options, settings_from_args
from ._foxglove import add_foxglove_option, live_view
from ._session import READY_TIMEOUT, add_namespace_option, namespace, ros_session, validate


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'hil', help='feed the part to a target with the example controller in the loop',
        description='Run the simulator with the feed_controller example node in the loop: it fires stroke '
                    'bursts until the part rests within feed.tolerance of feed.target_x (docs/hil.md).',
        epilog='Example: micro-feeder hil --lockstep --set feed.target_x=0.45e-3 --json')
    add_model_options(parser)
    parser.add_argument('--lockstep', action='store_true',
                        help='advance sim time only when the controller grants a step (deterministic)')
    parser.add_argument('--timeout', type=float, default=2.0, metavar='SIM_SECONDS',
                        help='give up after this much sim time (default 2 s)')
    parser.add_argument('--record', metavar='PATH', help='record every topic to this log (docs/logs.md)')
    parser.add_argument('--json', action='store_true', help='print one JSON object and nothing else')
    add_foxglove_option(parser)
    add_namespace_option(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    flat = settings_from_args(args)
    if not args.timeout > 0:
        raise CommandError('--timeout must be > 0')
    ns = namespace(args.namespace)
    validate(flat, controller=True)      # before the recorder creates the log
    with live_view(args.foxglove) as viewer, ros_session(args.record, ns, viewer) as session:
        from ..nodes.feed_controller import FeedController
        from ..nodes.simulator import Simulator

        sim = session.add(lambda: Simulator(context=session.context, namespace=ns,
                                            overrides={**flat, 'lockstep': args.lockstep}))
        end = sim.stop_at(args.timeout)     # at once: sim time runs while the other nodes are built
        if session.recorder is not None:     # the log starts before the loop does: the recorder hears the
            # simulator, and actuator/trajectory has its subscription besides the simulator's
            def heard() -> bool:
                return session.recorder_hears(sim) and sim.count_subscribers('actuator/trajectory') > 1
            deadline = time.monotonic() + READY_TIMEOUT
            session.spin(lambda: heard() or time.monotonic() > deadline)
            if not heard() and not session.stop:
                print(f'micro-feeder hil: started after {READY_TIMEOUT:g} s without the recorder on every topic: '
                      'the log may miss the first messages', file=sys.stderr)
        controller = session.add(lambda: FeedController(context=session.context, namespace=ns,
                                                        overrides={**flat, 'lockstep': args.lockstep}))
        start = time.perf_counter()
        session.spin(lambda: controller.done or bool(sim.error), end)
        wall = time.perf_counter() - start
        sim.pause()     # the loop thread no longer advances the state the outcome reads
        result = outcome(sim, controller, wall, session.close_log())
        fate = session.recording_fate()
        if fate:
            result['recording'] = fate     # the recording stopped early: where and why
    if args.json:
        print(json.dumps(result))
    else:
        print(controller.status_text() if controller.done else
              f'not finished after {sim.stepper.t:.6f} s sim time: {controller.status_text()}')
        print(f'sim time {result["sim_time_s"]:.6f} s in {wall:.2f} s wall; final mode {result["final_mode"]}'
              + (f'; log {result["log"]}' if result['log'] else '') + (f': {fate}' if fate else ''))
    return 0 if result['reached'] and not fate else 1


def outcome(sim: Any, controller: Any, wall_s: float, log: str | None) -> dict[str, Any]:
    """The JSON object of ``micro-feeder hil --json``.

    ``final_error_m``, ``final_mode`` and ``sim_time_s`` are the simulator's final state, read after
    :func:`run` paused it (so the three agree with each other); they can differ from the last pose the
    controller saw, which its ``status_text()`` reports. ``reached``, ``strokes``, ``bursts``,
    ``time_to_target_s``, ``status`` and ``reason`` are the controller's.
    """
    state = sim.stepper.state
    result = controller.result()
    return {'reached': result['reached'], 'time_to_target_s': result['time_to_target_s'],
            'strokes': result['strokes'], 'final_error_m': controller.goal.target_x - state.x,
            'final_mode': state.mode, 'status': result['status'], 'reason': result['reason'],
            'bursts': result['bursts'], 'sim_time_s': state.t, 'wall_time_s': wall_s,
            'error': sim.error, 'log': log}
