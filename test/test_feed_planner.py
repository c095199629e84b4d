"""FeedPlanner against synthetic plants (closed-form displacement per stroke) and in closed loop with the
real offline dynamics."""

from pathlib import Path

import pytest

from micro_feeder.control.feed_planner import Burst, FeedGoal, FeedPlanner
from micro_feeder.physics.parameters import ParameterError


def threshold_plant(amplitude: float, direction: float = -1.0, reversed_wave: bool = False) -> float:
    """Displacement per stroke (m): nothing below 70 um, growing like (A - 70 um)^2 above (the shape the
    default scenario shows), toward the bump centre (direction -1) unless the wave is reversed."""
    excess = max(amplitude - 70e-6, 0.0)
    sign = -direction if reversed_wave else direction
    return sign * 2.6e-6 * (excess / 30e-6) ** 2


def drive(planner: FeedPlanner, x: float, plant, max_bursts: int = 500) -> float:
    for _ in range(max_bursts):
        burst = planner.next_burst(x)
        if burst is None:
            return x
        moved = burst.count * plant(burst.amplitude_m, reversed_wave=burst.reversed_wave)
        planner.observe(burst, x, x + moved)
        x += moved
    raise AssertionError('planner never finished')


def test_reaches_target_toward_bump_with_adapted_amplitude():
    planner = FeedPlanner(FeedGoal(target_x=0.45e-3, tolerance=0.5e-6))
    x = drive(planner, 0.5e-3, threshold_plant)
    assert planner.status == 'reached'
    assert abs(x - 0.45e-3) <= 0.5e-6
    assert planner.strokes >= 50e-6 / 2.6e-6 * 0.8   # it used bursts, not one stroke at a time only
    assert planner.bursts < 60


def test_first_burst_is_a_single_probe_stroke_at_the_start_amplitude():
    goal = FeedGoal(target_x=0.0, tolerance=1e-6, amplitude_start=90e-6)
    assert FeedPlanner(goal).next_burst(0.5e-3) == Burst(90e-6, 1, False)


def test_small_amplitude_that_does_not_move_is_raised():
    planner = FeedPlanner(FeedGoal(target_x=0.45e-3, tolerance=1e-6, amplitude_start=40e-6))
    x = drive(planner, 0.5e-3, threshold_plant)
    assert planner.status == 'reached' and abs(x - 0.45e-3) <= 1e-6


def test_single_actuator_cannot_go_away_from_the_bump():
    planner = FeedPlanner(FeedGoal(target_x=0.6e-3, tolerance=1e-6))
    drive(planner, 0.5e-3, threshold_plant)
    assert planner.status == 'unreachable' and 'toward its bump centre' in planner.reason


def test_travelling_wave_reverses_direction():
    planner = FeedPlanner(FeedGoal(target_x=0.6e-3, tolerance=1e-6), travelling_wave=True)
    x = drive(planner, 0.5e-3, threshold_plant)
    assert planner.status == 'reached' and abs(x - 0.6e-3) <= 1e-6


def test_no_motion_at_the_largest_amplitude_gives_up():
    planner = FeedPlanner(FeedGoal(target_x=0.45e-3, tolerance=1e-6, amplitude_max=60e-6, amplitude_start=50e-6))
    drive(planner, 0.5e-3, threshold_plant)
    assert planner.status == 'unreachable' and 'do not move the part' in planner.reason


def test_goal_validation_names_the_parameter():
    with pytest.raises(ParameterError, match=r'feed\.amplitude_start'):
        FeedGoal(amplitude_start=200e-6, amplitude_max=150e-6)
    with pytest.raises(ParameterError, match=r'feed\.tolerance'):
        FeedGoal(tolerance=0.0)


def fire_offline(model, state, burst: Burst, pause_s: float, settle_s: float = 3e-3) -> None:
    """Fire ``burst`` from the state's time on the real dynamics and let the part settle."""
    phases = tuple(reversed(model.stroke.phases)) if burst.reversed_wave else model.stroke.phases
    stroke = model.stroke.replace(amplitude=burst.amplitude_m, count=burst.count, delay=state.t, pause=pause_s,
                                  phases=phases)
    fired = model.replace(stroke=stroke)
    model.advance(state, stroke.burst_end_s() + settle_s, source=fired.waveform())


TRAVELLING_WAVE = Path(__file__).parents[1] / 'config' / 'travelling_wave.yaml'


@pytest.mark.parametrize(('scenario', 'target_x'), [('single', 0.46e-3), ('single', 0.3e-3),
                                                    ('wave', 0.8e-3), ('wave', 0.9e-3), ('wave', 1.2e-3)])
def test_closed_loop_on_the_offline_dynamics(scenario, target_x):
    """The planner feeds the part to the target on the real physics: the default single actuator (toward the
    bump centre) and config/travelling_wave.yaml (both ways)."""
    from micro_feeder.physics.dynamics import FeederModel
    from micro_feeder.settings import load_settings

    flat = load_settings([TRAVELLING_WAVE] if scenario == 'wave' else [], [f'feed.target_x={target_x}'])
    model = FeederModel.from_settings(flat)
    state = model.initial_state()
    goal = FeedGoal.from_flat(flat)
    planner = FeedPlanner(goal, travelling_wave=scenario == 'wave')
    while (burst := planner.next_burst(state.x)) is not None:
        x_before = state.x
        fire_offline(model, state, burst, goal.stroke_pause)
        assert state.mode == 'stuck'
        planner.observe(burst, x_before, state.x)
    assert planner.status == 'reached', planner.reason
    assert abs(state.x - target_x) <= 1e-6
