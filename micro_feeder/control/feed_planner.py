"""Feed-to-target planning: which stroke burst to fire next, from where the part rests.

The planner knows nothing of the physics: it learns the displacement per stroke from what it observes
(the way a controller for real piezos must), and adapts:

* a first probe stroke at ``amplitude_start``;
* then ``count`` = as many strokes as fit in the remaining distance at the last measured displacement per
  stroke (at most ``max_count``);
* when one stroke would overshoot by more than the tolerance, a smaller amplitude (the displacement grows
  steeply with amplitude above the sliding threshold, so it is scaled by the cube root of the ratio);
* when strokes do not move the part, a larger amplitude, up to ``amplitude_max``;
* when the part moves away from the target (or overshoots it), the travelling wave is reversed if there is
  one, and when both directions have just moved it the wrong way the amplitude goes up (at small amplitudes
  a wave's direction depends on where the part sits); with a single actuator (which only draws the part
  toward its bump) the goal is then unreachable;
* after FUTILE_LIMIT bursts in a row that bring the part no closer, it gives up.

It is pure Python (no rclpy), so the same logic runs in the ROS node and in offline closed-loop tests.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..physics.parameters import ParameterError, ParameterGroup, param

AMPLITUDE_STEP_UP = 1.25      # amplitude factor after a burst that did not move the part
MIN_AMPLITUDE_FACTOR = 0.5    # never shrink the amplitude by more than this in one decision
STALL_LIMIT = 3               # bursts at the largest amplitude without motion before giving up
FUTILE_LIMIT = 10             # consecutive bursts that bring the part no closer before giving up
COUNT_SAFETY = 0.8            # fire this fraction of the strokes that would fit: the gain varies along the bump
NO_MOTION_FRACTION = 1e-3     # a displacement below this fraction of the tolerance counts as no motion


@dataclass(frozen=True)
class FeedGoal(ParameterGroup):
    """Where the part should go and how the controller may drive the actuators."""

    prefix = 'feed'

    target_x: float = param(0.4e-3, 'target position of the part along the feeder (frame feeder, x)', 'm')
    tolerance: float = param(1e-6, 'the part must rest within this distance of the target', 'm', gt=0)
    amplitude_start: float = param(100e-6, 'stroke amplitude of the first (probe) stroke', 'm', gt=0)
    amplitude_min: float = param(20e-6, 'smallest stroke amplitude the controller uses', 'm', gt=0)
    amplitude_max: float = param(150e-6, 'largest stroke amplitude the controller uses', 'm', gt=0)
    max_count: int = param(20, 'most strokes in one burst', ge=1)
    max_bursts: int = param(200, 'bursts before the controller gives up', ge=1)
    stroke_pause: float = param(1e-3, 'rest between the strokes of a burst: each stroke then starts with the part '
                                'at rest and displacements add up (back-to-back strokes of a travelling wave '
                                'nearly cancel)', 's', ge=0, le=1.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.amplitude_min <= self.amplitude_start <= self.amplitude_max:
            raise ParameterError('feed.amplitude_start', self.amplitude_start,
                                 f'between feed.amplitude_min ({self.amplitude_min:g}) and '
                                 f'feed.amplitude_max ({self.amplitude_max:g})')


@dataclass(frozen=True)
class Burst:
    """A burst to fire: ``count`` strokes of ``amplitude_m``; ``reversed_wave`` flips a travelling wave."""

    amplitude_m: float
    count: int
    reversed_wave: bool


@dataclass
class FeedPlanner:
    """Decides bursts until the part rests within tolerance of the target (see module docstring).

    Call :meth:`next_burst` with the resting position; after firing it, call :meth:`observe` with the
    resting position that followed. ``status`` is ``running``, ``reached`` or ``unreachable``.
    """

    goal: FeedGoal
    travelling_wave: bool = False
    status: str = 'running'
    reason: str = ''
    bursts: int = 0
    strokes: int = 0
    _amplitude: float = field(init=False)
    _per_stroke: float | None = field(default=None, init=False)
    _reversed: bool = field(default=False, init=False)
    _stalled: int = field(default=0, init=False)
    _wrong_way: int = field(default=0, init=False)
    _futile: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        self._amplitude = self.goal.amplitude_start

    def error(self, x: float) -> float:
        """Signed remaining distance target - x (m)."""
        return self.goal.target_x - x

    def next_burst(self, x: float) -> Burst | None:
        """The burst to fire with the part resting at ``x`` (m), or None when done (see ``status``)."""
        if self.status != 'running':
            return None
        error = self.error(x)
        if abs(error) <= self.goal.tolerance:
            self.status = 'reached'
            return None
        if self.bursts >= self.goal.max_bursts:
            return self._give_up(f'not within tolerance after {self.bursts} bursts')
        if self._per_stroke is not None and self._per_stroke * error < 0:
            if not self.travelling_wave:
                return self._give_up('the strokes move the part away from the target: one actuator only '
                                     'draws the part toward its bump centre (several actuators make a '
                                     'travelling wave that can go both ways)')
            if self._wrong_way >= 2:
                self._amplitude = min(self._amplitude * AMPLITUDE_STEP_UP, self.goal.amplitude_max)
            self._reversed = not self._reversed
            self._per_stroke = None
        count = 1
        if self._per_stroke is not None:
            per_stroke = abs(self._per_stroke)
            if abs(error) - per_stroke > self.goal.tolerance:
                count = max(1, min(int(COUNT_SAFETY * abs(error) / per_stroke), self.goal.max_count))
            elif abs(abs(error) - per_stroke) > self.goal.tolerance:
                ratio = max((abs(error) / per_stroke) ** (1.0 / 3.0), MIN_AMPLITUDE_FACTOR)
                self._amplitude = max(self._amplitude * ratio, self.goal.amplitude_min)
        return Burst(self._amplitude, count, self._reversed)

    def observe(self, burst: Burst, x_before: float, x_after: float) -> None:
        """Learn from a fired burst: the part moved from ``x_before`` to ``x_after`` (both at rest)."""
        self.bursts += 1
        self.strokes += burst.count
        moved = x_after - x_before
        closer = abs(self.error(x_after)) < abs(self.error(x_before))
        self._futile = 0 if closer else self._futile + 1
        if self._futile >= FUTILE_LIMIT:
            self._give_up(f'{FUTILE_LIMIT} bursts in a row brought the part no closer to the target')
            return
        self._wrong_way = self._wrong_way + 1 if moved * self.error(x_before) < 0 else 0
        if abs(moved) >= NO_MOTION_FRACTION * self.goal.tolerance:
            self._stalled = 0
            self._per_stroke = moved / burst.count
            return
        self._per_stroke = None
        if self._amplitude >= self.goal.amplitude_max:
            self._stalled += 1
            if self._stalled >= STALL_LIMIT:
                self._give_up(f'strokes of {self._amplitude * 1e6:.0f} um do not move the part')
        self._amplitude = min(self._amplitude * AMPLITUDE_STEP_UP, self.goal.amplitude_max)

    def _give_up(self, reason: str) -> None:
        self.status = 'unreachable'
        self.reason = reason
