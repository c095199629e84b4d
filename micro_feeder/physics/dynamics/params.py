"""Parameter groups of the particle dynamics: integration, detachment and landing rules."""

from __future__ import annotations

from dataclasses import dataclass

from ..parameters import ParameterGroup, param

FRICTION_LOGICS = ('events', 'threshold')
METHODS = ('dopri5', 'rk4')
EVENT_SEARCHES = ('dips', 'step_ends')
LANDING_VELOCITIES = ('relative', 'absolute')
LANDING_LAWS = ('keep', 'coulomb', 'stick')


@dataclass(frozen=True)
class IntegrationParams(ParameterGroup):
    """How the motion is integrated (docs/dynamics.md §3)."""

    prefix = 'integration'

    method: str = param('dopri5', "'dopri5': adaptive Dormand-Prince 5(4); 'rk4': fixed-step classical "
                        "RK4 (the seed's scheme; always used by friction_logic threshold)", choices=METHODS)
    dt: float = param(1e-4, 'rk4: the step; dopri5: the largest step', 's', ge=1e-7, le=1e-3)
    tolerance: float = param(1e-10, 'dopri5: error allowed per step on positions (m); on velocities '
                             'tolerance / dt (m/s); at least 1e-15 m (below, double precision cannot meet it and the '
                             'step shrinks without end)', 'm', ge=1e-15, le=1e-3)
    check_step: float = param(1e-4, 'largest step while stuck (nothing is integrated then; with '
                              'event_search dips, not the resolution of the stick-limit and pull-off checks)',
                              's', ge=1e-7, le=1e-3)
    event_tolerance: float = param(1e-9, 'time tolerance of event location', 's', ge=1e-13, le=1e-6)
    event_search: str = param('dips', "'dips': a margin that dips past its event inside a step is found (its "
                              "minimum located, docs/events.md); 'step_ends': tested where steps end only "
                              "(faster; misses dips shorter than a step)", choices=EVENT_SEARCHES)
    friction_logic: str = param('events', "'events': exact stick/slip switching by event location; "
                                "'threshold': the seed's threshold-velocity logic V_th = Q_max dt / m",
                                choices=FRICTION_LOGICS)
    convective_terms: bool = param(True, 'keep 2 h_xt xdot + h_xx xdot^2 in the normal load (false: the '
                                   "seed's form, normal acceleration = surface acceleration)")
    settling_time: float = param(2e-3, 'default run length beyond the end of the last stroke', 's', ge=0, le=1e4)
    settle_max: float = param(1.0, 'a run with no duration goes on past its default length until the part is '
                              'stuck again, for at most this much more sim time (then it is reported not settled)',
                              's', ge=0, le=1e4)


@dataclass(frozen=True)
class DetachParams(ParameterGroup):
    """When the part leaves the surface (docs/dynamics.md §1)."""

    prefix = 'detach'

    include_weight: bool = param(True, 'take-off when N + F_po < 0 with the weight inside N (false: the '
                                 "seed's test of the inertial load alone against F_po)")


@dataclass(frozen=True)
class LandingParams(ParameterGroup):
    """What velocity a landing part keeps (docs/dynamics.md §1, docs/tracks.md)."""

    prefix = 'landing'

    law: str = param('keep', "tangential velocity at a landing: 'keep' it (the seed's rule); 'coulomb': it changes "
                     'by at most contact.mu times the normal velocity lost (a Coulomb impulse); '
                     "'stick': the part takes the surface's", choices=LANDING_LAWS)
    restitution: float = param(0.0, 'normal restitution e_n: the part leaves the surface again with e_n times '
                               'the normal velocity it arrived with (0: it stays down); a bounce whose flight would '
                               'last less than integration.event_tolerance x 1000 is plastic, so chatter ends',
                               '', ge=0.0, lt=1.0)
    velocity: str = param('relative', "'relative': keep the tangential velocity relative to the surface; "
                          "'absolute': keep the tangential component of the absolute velocity (seed)",
                          choices=LANDING_VELOCITIES)


def dynamics_parameter_groups() -> list[type[ParameterGroup]]:
    """The parameter groups of the surface, stroke, piezo and dynamics (for settings.PARAMETER_GROUPS)."""
    from ..piezo import PiezoParams
    from ..surface import SurfaceParams, TrackParams
    from ..waveforms import StrokeParams
    return [SurfaceParams, TrackParams, StrokeParams, PiezoParams, IntegrationParams, DetachParams, LandingParams]
