"""The compiled kernel's data layout: the immutable :class:`KernelModel` (MuJoCo's ``mjModel``) and the
named indices into the evolving arrays (``mjData``) and the output rows.

Data passed around the kernel (all SI):

* ``model``: a :class:`KernelModel`, the immutable inputs by name;
* ``src``: a :class:`~micro_feeder.physics.waveforms.StrokeTable` as a tuple; channels 0..n_act-1 are
  the actuators (a track's one channel is its displacement along the vibration line; the kernel works in
  the frame that follows the track's tangential motion, whose acceleration s̈ cos β and gravity's g sin α
  along the track act on the part as a base acceleration, and whose surface is flat at height s sin β),
  channel n_act (present when ``model.has_base``) the horizontal base acceleration of the test-only
  flat-surface check (its s̈ is the base acceleration);
* ``y``: state vector. In contact ``[x, ẋ, 0, 0]``, in flight ``[x, v_x, z, v_z]``; then, with the piezo
  model, ``[s_k, ṡ_k]`` per actuator;
* ``iv`` (int64) and ``fs`` (float64): discrete state and bookkeeping, indexed by ``IV_*`` / ``FS_*``;
* ``aux``: quantities of the last right-hand-side evaluation, indexed by ``AUX_*``.

Every mode has two *margins*, positive while the mode lasts; an event is a margin reaching 0:
stuck: Q_max − |T_req| and N_det + F_po; sliding: dir·ẋ (with surface.thickness: dir·dX/dt, the slip relative
to the surface's material) and N_det + F_po; flying: the gap δ.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

STUCK, SLIDING, FLYING = 0, 1, 2
LANDING_KEEP, LANDING_COULOMB, LANDING_STICK = 0, 1, 2      # landing.law, in LANDING_LAWS order


class KernelModel(NamedTuple):
    """Everything the kernel reads and never changes, by name (SI units): built by
    :class:`~micro_feeder.physics.dynamics.model.FeederModel`. numba compiles it as a typed tuple."""

    mass: float                 # particle mass (kg)
    gravity: float              # g (m/s²)
    pull_off: float             # pull-off force F_po (N)
    dt: float                   # RK4 step / largest DOPRI5 step (s)
    tolerance: float            # DOPRI5 error allowed per step on positions (m)
    check_step: float           # largest step while stuck (s)
    event_tolerance: float      # time tolerance of event location (s)
    cutoff_radius: float        # surface.cutoff as a radius in widths (inf: exact sum; docs/dynamics.md)
    min_width: float            # the narrowest actuator width (m)
    max_width: float            # the widest actuator width (m)
    piezo_omega: float          # piezo stack natural angular frequency (rad/s)
    piezo_zeta: float           # piezo stack damping ratio
    piezo_min: float            # piezo travel limits (m)
    piezo_max: float
    lift: float                 # track: sin β, the normal part of the vibration (0 for bumps)
    shake: float                # track: cos β, the tangential part of the vibration (0 for bumps)
    slope_acc: float            # track: g sin α, gravity along the track (m/s², 0 for bumps)
    landing_mu: float           # landing law coulomb: μ of the tangential impulse
    restitution: float          # normal restitution e_n at a landing (0: plastic)
    half_thickness: float       # surface.thickness / 2 (m): the top surface moves along x by u = −(t/2) ∂h/∂x
    bounce_min_flight: float    # s: a bounce whose flight would be shorter is plastic (chatter ends)
    adaptive: bool              # DOPRI5 (else fixed-step RK4)
    threshold: bool             # the seed's threshold-velocity friction logic (else exact events)
    dip_search: bool            # event_search 'dips': margins' minima inside steps are searched
    convective: bool            # 2 h_xt ẋ + h_xx ẋ² kept in the normal load
    include_weight: bool        # take-off test with the weight inside N
    landing_relative: bool      # landing keeps the velocity relative to the surface
    piezo: bool                 # piezo stack dynamics integrated (state y[4:])
    has_base: bool              # test-only base-acceleration channel after the actuators
    track: bool                 # a rigid track (surface.kind track): flat, moving along β; channel 0 its stroke
    record: bool                # write one output row per step and event
    centers: np.ndarray         # actuator centres (m), in increasing order
    widths: np.ndarray          # actuator widths (m)
    load_n: np.ndarray          # contact tables: normal load (N) ...
    q_max_n: np.ndarray         # ... and Q_max at that load (N), separation (m) at that load
    separation_m: np.ndarray
    gap_m: np.ndarray           # flight table: gap (m) ...
    attraction_n: np.ndarray    # ... and adhesive attraction (N)
    n_actuators: int
    landing_law: int            # LANDING_KEEP, LANDING_COULOMB or LANDING_STICK
    lift_channel: int           # track: the channel whose stroke moves the track normal to its surface (0 or 1)


# iv: discrete state. IV_ENTRY_COUNTER: the counter incremented when the current mode was entered (-1
# none), IV_PREV_MODE: the mode before it; both serve "a mode that ends within the event tolerance of
# its start is treated as not entered".
# IV_AHEAD_*: the step taken past the last target (see ``advance``); IV_START_KNOWN: the dip search
# knows the margins' slopes where the next step starts (FS_START_SLOPE*).
(IV_MODE, IV_DIR, IV_FRESH, IV_STICK_TO_SLIP, IV_SLIP_TO_STICK, IV_TAKE_OFF, IV_LANDING,
 IV_ENTRY_COUNTER, IV_PREV_MODE, IV_AHEAD_WHICH, IV_AHEAD_GRAZING, IV_START_KNOWN) = range(12)
N_IV = 12
COUNTERS = (IV_STICK_TO_SLIP, IV_SLIP_TO_STICK, IV_TAKE_OFF, IV_LANDING)

# fs: continuous bookkeeping (FS_H: the adaptive step size to try next; FS_AHEAD_T0/T1: start and end of
# the step taken past the last target, T1 NaN when there is none; FS_START_SLOPE0/1: the margins' slopes
# (per second) where the next step starts, when IV_START_KNOWN)
FS_T, FS_T_ENTRY, FS_MAX_SPEED, FS_H, FS_AHEAD_T0, FS_AHEAD_T1, FS_START_SLOPE0, FS_START_SLOPE1 = range(8)
N_FS = 8
N_SCRATCH = 11

# aux: quantities of the last evaluation; AUX_FELT_LO/HI: the range of actuators whose strokes the last
# evaluation filled in ``st`` (the other columns are stale: read ``st`` through ``rhs.felt``); AUX_JET: where
# a contact evaluation leaves the surface's h_xx, h_tt, h_xt, h_ttt, h_ttx, h_xxt, h_xxx at the part (for
# ``rhs.margin_slopes``, in that order); AUX_T_RATE: dT_req/dt where ``rhs.margin_slopes`` last found the stuck
# margin's slope (NaN where it has no closed form)
(AUX_N, AUX_T_REQ, AUX_QMAX, AUX_L, AUX_H, AUX_HX, AUX_HT, AUX_GAP, AUX_XS, AUX_LOAD_INDEX,
 AUX_ROOT_SLOPE, AUX_FELT_LO, AUX_FELT_HI, AUX_JET) = range(14)
AUX_T_RATE = AUX_JET + 7
# with surface.thickness (``rhs.material_load``): the material point X under the part, its velocity along x
# (m/s) and z, the part's slip rate dX/dt relative to it, 1 + ∂u/∂X, |∂P/∂X| and the acceleration along x
# (m/s²) the motion at that slip rate has before friction acts
AUX_MAT_X, AUX_MAT_VX, AUX_MAT_VZ, AUX_SLIP, AUX_STRETCH, AUX_ARC, AUX_MAT_AX = range(AUX_JET + 8, AUX_JET + 15)
N_AUX = AUX_JET + 15

# Columns of a recorded row (then one stroke column per actuator).
(C_T, C_MODE, C_X, C_Z, C_XD, C_ZD, C_THETA, C_N, C_FRICTION, C_QMAX, C_SEPARATION, C_GAP, C_H,
 C_HT) = range(14)
N_FIXED_COLUMNS = 14
COLUMN_NAMES = ('t', 'mode', 'x', 'z', 'xdot', 'zdot', 'theta', 'normal_load', 'friction', 'q_max',
                'separation', 'gap', 'surface_height', 'surface_velocity')

# Kernel return codes.
DONE, EVENTS_FULL, RECORDS_FULL, NON_FINITE, EVENT_NOT_LOCATED, CHATTER = range(6)

# Event kinds (recorded with each mode change); REVERSAL: a slide changing direction (not counted).
STICK_TO_SLIP, SLIP_TO_STICK, TAKE_OFF, LANDING, REVERSAL = range(5)
