"""Benchmark: the simulator node's own work in the soak's scenario, offline (no ROS graph): where its CPU
goes, apart from the middleware.

Usage: .venv/bin/python bench/bench_node_work.py [--cases 1,16,64] [--json PATH | --no-json]

Per case (the travelling wave of bench/bench_soak.py: n actuators 1 mm apart, phases (k mod 4)/4, streamed
as the actuator streams it: 20 ms windows of knots, kept 0.2 s ahead), CPU time of this thread, best of 3:

* a tick: what the node's loop does every 1 ms besides publishing: ``Stepper.advance`` by 1 ms, ``observe``,
  serializing the state messages and the transitions of that millisecond. A 0.8 ms sleep between ticks
  lets the caches go cold as they do in the node.
* a window: what the intake thread does per streamed trajectory message: parse the CDR bytes and apply the
  knots to the schedule (which checks the interpolated strokes against the piezo limits).

No target of its own (a report): it prints the share of bench_soak's CPU targets (25 / 35 / 50 % of a
core for 1 / 16 / 64 actuators, i.e. 250 / 350 / 500 µs per 1 ms tick) that this work takes. The rest of
the budget is for publishing (nine messages a tick) and the middleware's threads, which only bench_soak sees.
Results: bench/results/bench_node_work.json.
"""

from __future__ import annotations

import argparse
import os
import time

import results_json
from bench_soak import CASES, wave_settings
from results_json import figure

from micro_feeder.interface import messages, stamps, trajectory_cdr
from micro_feeder.interface.names import joint_names
from micro_feeder.interface.transitions import TransitionEncoder
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.sim.commands import parse_trajectory_cdr
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import StrokeStream

TICK, LEAD, WINDOW = 1e-3, 0.2, 0.02             # s
BUDGET_US = {n: cpu_percent * TICK * 1e4 for n, (_minutes, cpu_percent) in CASES.items()}   # µs per tick


class Feeder:
    """A stepper fed by a stroke stream, as the simulator is by the actuator."""

    def __init__(self, n: int):
        flat = wave_settings(n)
        self.stepper = Stepper(build_model(flat))
        self.stream = StrokeStream(StrokeParams.from_flat({**flat, 'stroke.count': 1}), 0, n, 0, window=WINDOW,
                                   max_points=2000, knots_per_stroke=0)
        self.names = joint_names(n)
        self.state_messages = messages.StateMessages(self.names)
        self.transitions = TransitionEncoder('simulator')
        self.window_cpu, self.windows = 0.0, 0

    def feed(self) -> None:
        """Send and take the windows that keep the strokes scheduled ``LEAD`` ahead (intake CPU counted)."""
        while self.stream.scheduled_until < self.stepper.t + LEAD:
            stamp_ns, offsets_ns, knots = self.stream.next_window()
            data = trajectory_cdr.encode(self.names, offsets_ns, knots[0], knots[1], knots[2],
                                         stamps.to_time(stamp_ns * 1e-9))
            start = time.thread_time()
            self.stepper.command_trajectory(parse_trajectory_cdr(data, self.names, self.stepper.limits))
            self.window_cpu += time.thread_time() - start
            self.windows += 1

    def tick(self) -> float:
        """One tick's work; returns its CPU time (s)."""
        start = time.thread_time()
        events = self.stepper.advance(self.stepper.t + TICK)
        observation = self.stepper.observe()
        self.state_messages.update(observation, observation.stroke_velocities)
        for event in events:
            if event.kind != 'reversal':
                self.transitions.encode(event)
        return time.thread_time() - start


def measure(n: int, ticks: int = 1000) -> tuple[float, float, float]:
    """(µs per tick, µs per window, windows per tick), best of 3 runs of ``ticks`` after 200 to warm up."""
    feeder = Feeder(n)
    for _ in range(200):
        feeder.feed()
        feeder.tick()
    best = (float('inf'), float('inf'), 0.0)
    for _ in range(3):
        feeder.window_cpu, feeder.windows = 0.0, 0
        tick_cpu = 0.0
        for _ in range(ticks):
            feeder.feed()
            tick_cpu += feeder.tick()
            time.sleep(0.8 * TICK)
        per_window = feeder.window_cpu / max(feeder.windows, 1)
        if tick_cpu < best[0] * ticks:
            best = (tick_cpu / ticks, per_window, feeder.windows / ticks)
    return best[0] * 1e6, best[1] * 1e6, best[2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--cases', default='1,16,64', help='actuator counts, comma-separated (default 1,16,64)')
    results_json.add_arguments(parser, 'bench_node_work')
    args = parser.parse_args()
    load = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    figures = []
    for n in (int(c) for c in args.cases.split(',')):
        tick_us, window_us, windows_per_tick = measure(n)
        share = tick_us + window_us * windows_per_tick
        figures += [
            figure(f'tick_{n}_us', f'{n} actuator(s): one 1 ms tick (advance, observe, serialize)', round(tick_us, 1),
                   'µs'),
            figure(f'window_{n}_us', f'{n} actuator(s): one streamed window (parse, schedule, limit check)',
                   round(window_us), 'µs', note=f'{windows_per_tick:.3f} windows per tick'),
            figure(f'share_{n}_pct', f'{n} actuator(s): tick and windows, share of bench_soak\'s CPU budget '
                   f'({BUDGET_US[n]:.0f} µs a tick)', round(100 * share / BUDGET_US[n]), '%',
                   note=f'{share:.1f} µs per 1 ms tick, before publishing')]
        print(f'{n:2d} actuators: tick {tick_us:6.1f} µs, window {window_us:6.0f} µs x {windows_per_tick:.3f} per tick'
              f' = {share:6.1f} µs per 1 ms tick, {100 * share / BUDGET_US[n]:.0f} % of the node budget '
              f'{BUDGET_US[n]:.0f} µs (bench_soak CPU target), before publishing', flush=True)
    results_json.save(args, 'bench_node_work', 'The simulator node\'s own work, offline', figures, load_before=load,
                      seconds=time.perf_counter() - started,
                      purpose='CPU time of what the simulator node does per tick and per streamed window in '
                              'bench_soak\'s travelling wave, without ROS: a report, no target of its own.')


if __name__ == '__main__':
    main()
