"""``micro-feeder calibrate``: stepped runs recorded by the real recorder from the simulator node, with two
parameters changed from their defaults, are fitted together from perturbed starting values back to those
values (to 1 %); a parameter that has no effect on the log is reported as not identifiable."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
from node_helpers import Probe
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_helpers import wait_until

from micro_feeder.cli import main
from micro_feeder.explore.calibrate import CalibrationError, calibrate, residuals
from micro_feeder.explore.runners import InProcess, LocalProcesses
from micro_feeder.interface import messages, stamps
from micro_feeder.interface.names import joint_names
from micro_feeder.nodes.recorder import Recorder
from micro_feeder.nodes.simulator import Simulator
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.settings import known_parameters
from micro_feeder.sim.stream import sample_waveform

STEP = 1e-4          # s per simulator/step
STEPS = 80           # 6 strokes at 1.2 kHz (5 ms), then 3 ms at rest
TRUE = {'contact.friction_scale': 0.0135, 'particle.x0': 0.62e-3}     # defaults: 0.010814, 0.5e-3
TIMEOUT = 60.0


def _record(context: Context, path: Path, stroke: StrokeParams) -> None:
    """A stepped run of the simulator (``TRUE`` parameters) driven by one burst of ``stroke``, recorded."""
    recorder = Recorder(context=context, parameter_overrides=[Parameter('output', value=str(path)),
                                                              Parameter('flush_period', value=0.2)])
    sim = Simulator(context=context, overrides={'start_paused': True, 'step_period': STEP, **TRUE})
    probe = Probe(context=context)
    executor = SingleThreadedExecutor(context=context)
    for node in (recorder, sim, probe):
        executor.add_node(node)
    try:
        wait_until(lambda: sim.count_subscribers('particle/pose') >= 2
                   and recorder.received['/simulator/parameters'] >= 1
                   and probe.publishers_['actuator/trajectory'].get_subscription_count() >= 3,
                   TIMEOUT, executor=executor, what='recorder and probe matched')
        times, pos, vel, acc = sample_waveform(stroke, 1, 40)
        probe.publish('actuator/trajectory', messages.trajectory(joint_names(1), times, pos, vel, acc,
                                                                 stamps.to_time(0.0)), executor)
        wait_until(lambda: recorder.received['/simulator/command_receipts'] == 1, TIMEOUT, executor=executor,
                   what='receipt')
        at_start = recorder.received['/particle/pose']
        probe.step(executor, STEPS)
        wait_until(lambda: recorder.received['/particle/pose'] == at_start + STEPS, TIMEOUT, executor=executor,
                   what='every pose recorded')
    finally:
        executor.shutdown()
        recorder.close()
        for node in (probe, sim, recorder):
            node.destroy_node()


def _record_log(folder: Path, name: str, stroke: StrokeParams) -> Path:
    context = Context()
    rclpy.init(context=context)
    try:
        _record(context, folder / name, stroke)
    finally:
        rclpy.shutdown(context=context)
    return folder / name


@pytest.fixture(scope='module')
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    yield _record_log(tmp_path_factory.mktemp('calibrate'), 'stepped',
                      StrokeParams(count=6, amplitude=100e-6, frequency=1200.0))


@pytest.fixture(scope='module')
def second_log(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The same feeder driven by a different burst (4 strokes, 90 um, 1 kHz)."""
    yield _record_log(tmp_path_factory.mktemp('calibrate'), 'other', StrokeParams(count=4, amplitude=90e-6))


def test_the_true_parameters_reproduce_the_log_exactly(recorded: Path) -> None:
    assert abs(residuals(str(recorded), TRUE)).max() == 0.0                 # resim's machinery: bit for bit
    defaults = {name: known_parameters()[name][1] for name in TRUE}
    assert abs(residuals(str(recorded), defaults)).max() > 1e-6             # the defaults do not


def test_two_parameters_are_recovered_to_one_percent(recorded: Path, second_log: Path) -> None:
    start = {'contact.friction_scale': 0.0115, 'particle.x0': 0.55e-3}      # 15 % and 11 % off
    with LocalProcesses(2) as runner:
        result = calibrate([str(recorded), str(second_log)], start, runner)
    assert result.residual_count == sum(len(residuals(str(log), TRUE)) for log in (recorded, second_log))
    assert abs(residuals(str(second_log), start)).max() > 1e-6      # the second log weighs in
    assert result.converged, result.problems
    for fitted in result.parameters:
        assert fitted.identifiable and fitted.value == pytest.approx(TRUE[fitted.name], rel=0.01), fitted
        assert 0 <= fitted.sigma < 0.01 * abs(fitted.value)
    assert result.rms < 1e-3 * result.rms_start and result.evaluations > 2


def test_a_parameter_without_effect_is_reported_and_the_json_is_one_object(recorded: Path, tmp_path, capsys):
    # the stroke comes from the recorded commands, so the analytic waveform's frequency plays no part
    code = main(['calibrate', str(recorded), '--fit', 'contact.friction_scale,stroke.frequency',
                 '--set', 'contact.friction_scale=0.012', '--processes', '1', '--json', '--out', str(tmp_path),
                 '--plot'])
    result = json.loads(capsys.readouterr().out)
    assert code == 1
    assert result['parameters']['stroke.frequency']['identifiable'] is False
    assert any('stroke.frequency has no effect' in p for p in result['problems'])
    assert result['parameters']['contact.friction_scale']['value'] == pytest.approx(0.0135, rel=0.01)
    assert (tmp_path / 'calibrate.png').stat().st_size > 10_000


def test_a_fit_stopped_early_says_it_did_not_converge(recorded: Path) -> None:
    result = calibrate([str(recorded)], {'contact.friction_scale': 0.0115}, InProcess(), max_evaluations=1)
    assert not result.converged
    assert any(p.startswith('did not converge within 1 evaluations') for p in result.problems), result.problems


def test_bad_starts_are_refused(recorded: Path) -> None:
    with pytest.raises(CalibrationError, match='non-zero'):
        calibrate([str(recorded)], {'stroke.delay': 0.0}, InProcess())
    with pytest.raises(CalibrationError, match='numeric model parameter'):
        calibrate([str(recorded)], {'stroke.waveform': 1.0}, InProcess())
