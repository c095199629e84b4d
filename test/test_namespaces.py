"""Several feeders on one graph: two complete ``micro-feeder run --namespace`` feeders (simulator, actuator,
recorder each) side by side in one domain, with different parameters, and no crosstalk; ``__node``
remapping moves a simulator's services and its own topics."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from ros_helpers import wait_until

from micro_feeder.logs.reader import LogReader
from micro_feeder.nodes.simulator import Simulator

FEEDERS = {'/feeder1': 0.5e-3, '/feeder2': 0.3e-3}      # namespace: particle.x0 (m)


def test_two_namespaced_feeders_run_side_by_side_without_crosstalk(ros_context: Context, tmp_path: Path) -> None:
    exe = shutil.which('micro-feeder', path=str(Path(sys.executable).parent))
    runs = {ns: subprocess.Popen([exe, 'run', '--namespace', ns.strip('/'), '--duration', '6',
                                  '--record', str(tmp_path / ns.strip('/')), '--set', f'particle.x0={x0}',
                                  '--set', f'stroke.count={2 if ns == "/feeder1" else 3}'],
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            for ns, x0 in FEEDERS.items()}
    graph = Node('graph_probe', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(graph)
    try:
        wanted = {f'{ns}/{name}' for ns in FEEDERS for name in ('simulator/step', 'simulator/reset',
                                                                 'simulator/pause', 'recorder/stop')}
        seen: set[str] = set()
        clocks: set[int] = set()

        def look() -> bool:
            seen.update(name for name, _ in graph.get_service_names_and_types())
            clocks.add(graph.count_publishers('/clock'))
            return wanted <= seen

        wait_until(look, 120, executor=executor, what=f'the services {sorted(wanted - seen)}')
        assert clocks == {0}         # namespaced simulators leave /clock alone
        outputs = {ns: run.communicate(timeout=120)[0] for ns, run in runs.items()}
    finally:
        executor.shutdown()
        graph.destroy_node()
        for run in runs.values():
            if run.poll() is None:
                run.kill()
                run.communicate()
    for ns, x0 in FEEDERS.items():
        assert runs[ns].returncode == 0, outputs[ns]
        assert '1 bursts sent, 0 rejected' in outputs[ns], outputs[ns]
        log = LogReader(tmp_path / ns.strip('/'))
        topics = set(log.topics)
        assert all(t.startswith(ns + '/') or t == '/diagnostics' for t in topics), topics
        assert f'{ns}/particle/pose' in topics and '/clock' not in topics
        receipts = [m.message.frame_id for m in log.messages([f'{ns}/simulator/command_receipts'])]
        assert receipts == ['actuator/trajectory'], receipts        # its own actuator's burst only
        poses = [m.message.pose.position.x for m in log.messages([f'{ns}/particle/pose'])]
        assert abs(poses[0] - x0) < 1e-12 and all(abs(x - x0) < 50e-6 for x in poses)
        loops = {s.name for m in log.messages(['/diagnostics']) for s in m.message.status if s.name.endswith(': loop')}
        assert f'{ns.strip("/")}/simulator: loop' in loops, loops     # told apart on the shared /diagnostics


def test_node_remapping_moves_the_services_and_own_topics(ros_context: Context) -> None:
    sim = Simulator(context=ros_context, cli_args=['--ros-args', '-r', '__node:=sim_a', '-r', '__ns:=/lab'])
    try:
        services = {name for name, _ in sim.get_service_names_and_types_by_node('sim_a', '/lab')}
        assert {'/lab/sim_a/step', '/lab/sim_a/reset', '/lab/sim_a/pause'} <= services, services
        topics = {p.topic_name for p in sim.publishers}
        assert {'/lab/sim_a/parameters', '/lab/sim_a/command_receipts', '/lab/particle/pose'} <= topics, topics
        assert '/clock' not in topics
    finally:
        sim.destroy_node()
