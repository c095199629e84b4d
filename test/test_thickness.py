"""surface.thickness (issue 27): the top surface of a bending plate of thickness t also moves along the feeder,
u = −(t/2) ∂h/∂X at each material point X (Kirchhoff).

* The contact law on that moving curve against an independent evaluation: the surface P(X, t) = (X + u, h)
  differentiated by finite differences of the vectorised profile (not the kernel's closed forms), and
  Newton's law m a = N n + T τ − m g ẑ solved as a 2×2 system for N and the slip acceleration.
* A part held stuck follows its material point, x(t) = X − (t/2) h_X(X, t), the closed form.
* Bad combinations are refused with the parameter named.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from micro_feeder.physics.dynamics import FeederModel, layout
from micro_feeder.physics.dynamics.rhs import material_load
from micro_feeder.physics.parameters import ParameterError
from micro_feeder.physics.waveforms import StrokeParams, waveform_table

CENTERS, WIDTHS = (0.0, 0.7e-3), (0.5e-3, 0.6e-3)
THICKNESS = 1e-3


def _profile(x: float, s: np.ndarray) -> float:
    u = (x - np.asarray(CENTERS)) / np.asarray(WIDTHS)
    return float(np.exp(-0.5 * u * u) @ s)


def _surface_point(material_x: float, t: float, strokes) -> np.ndarray:
    """P(X, t) = (X − (t/2) h_X, h), h_X by a central difference of the profile (independent of the kernel)."""
    s = strokes(t)
    d = 1e-7
    slope = (_profile(material_x + d, s) - _profile(material_x - d, s)) / (2 * d)
    return np.array([material_x - 0.5 * THICKNESS * slope, _profile(material_x, s)])


def _derivatives(material_x: float, t: float, strokes) -> dict[str, np.ndarray]:
    """P_X, P_t, P_XX, P_Xt, P_tt by 4th-order central differences of :func:`_surface_point` (steps of 1/50 of
    a bump width and 1/100 of a stroke period: truncation ~1e-6 relative)."""
    dx, dt = 1e-5, 1e-5
    first = np.array([1.0, -8.0, 0.0, 8.0, -1.0]) / 12.0           # f' h at offsets -2..2
    second = np.array([-1.0, 16.0, -30.0, 16.0, -1.0]) / 12.0      # f'' h²
    grid = np.array([[_surface_point(material_x + i * dx, t + j * dt, strokes) for j in range(-2, 3)]
                     for i in range(-2, 3)])                        # (X offset, t offset, xz)
    return {'X': first @ grid[:, 2] / dx, 't': first @ grid[2, :] / dt,
            'XX': second @ grid[:, 2] / dx ** 2, 'tt': second @ grid[2, :] / dt ** 2,
            'Xt': np.einsum('i,j,ijk->k', first, first, grid) / (dx * dt)}


def _model() -> FeederModel:
    return FeederModel.from_settings({'surface.centers': list(CENTERS), 'surface.widths': list(WIDTHS),
                                      'surface.thickness': THICKNESS, 'stroke.phases': [0.0, 0.3],
                                      'stroke.amplitude': 120e-6})


@pytest.mark.parametrize('material_x,t,slip', [(0.25e-3, 0.35e-3, 0.0), (0.4e-3, 0.52e-3, 0.05),
                                               (-0.3e-3, 0.77e-3, -0.12), (0.9e-3, 0.6e-3, 0.2)])
def test_normal_load_and_slip_acceleration_against_newton_on_the_moving_curve(material_x: float, t: float,
                                                                              slip: float) -> None:
    model = _model()
    table = waveform_table(model.stroke, 2)
    strokes = lambda time: table.evaluate(time)[0]          # noqa: E731  (s per actuator, m)
    d = _derivatives(material_x, t, strokes)
    position = _surface_point(material_x, t, strokes)
    xdot = d['t'][0] + d['X'][0] * slip                      # the part's velocity along x on the point X
    m, g = model.particle.mass, model.particle.gravity
    # the kernel: strokes s, ṡ, s̈, s⃛ at t in its work array; every actuator felt
    st = np.zeros((4, 2))
    values = table.evaluate(t)
    st[:3] = values
    d3 = 1e-7
    st[3] = (table.evaluate(t + d3)[2] - table.evaluate(t - d3)[2]) / (2 * d3)
    aux = np.zeros(layout.N_AUX)
    aux[layout.AUX_FELT_LO], aux[layout.AUX_FELT_HI] = 0, 2
    material_load(float(position[0]), float(xdot), False, st, 0.0, model._kernel_model, aux)
    assert aux[layout.AUX_MAT_X] == pytest.approx(material_x, rel=0, abs=1e-12)
    assert aux[layout.AUX_SLIP] == pytest.approx(slip, rel=1e-6, abs=2e-6 * abs(d['t'][0]))
    # independent: m (P_tt + 2 P_Xt Ẋ + P_XX Ẋ² + P_X Ẍ) = N n + T τ − m g ẑ, for a friction force T
    arc = float(np.hypot(*d['X']))
    tangent = d['X'] / arc
    normal = np.array([-tangent[1], tangent[0]])
    known = d['tt'] + 2 * d['Xt'] * slip + d['XX'] * slip ** 2
    friction = 0.37 * aux[layout.AUX_N]
    # unknowns N, Ẍ: m P_X Ẍ − N n = T τ − m g ẑ − m known
    system = np.column_stack([m * d['X'], -normal])
    slip_acc, load = np.linalg.solve(system, friction * tangent - m * np.array([0.0, g]) - m * known)
    assert aux[layout.AUX_N] == pytest.approx(load, rel=2e-5)
    kernel_slip_acc = (friction - aux[layout.AUX_T_REQ]) / (m * aux[layout.AUX_ARC])
    assert kernel_slip_acc == pytest.approx(slip_acc, rel=2e-5, abs=1e-6 * abs(known).max())
    # the part's acceleration along x, as the kernel integrates it
    xddot = aux[layout.AUX_MAT_AX] + aux[layout.AUX_STRETCH] * kernel_slip_acc
    assert xddot == pytest.approx(known[0] + d['X'][0] * slip_acc, rel=2e-5, abs=1e-6 * abs(known).max())


def test_a_stuck_part_follows_its_material_point() -> None:
    """Weak strokes (8 µm at 300 Hz, strong adhesion) never unstick the part: it rides its material point,
    x(t) = X − (t/2) h_X(X, t) and ẋ = −(t/2) h_Xt(X, t), X = x0 (the strokes start at rest), to the
    integration's tolerance."""
    x0 = 0.35e-3
    model = FeederModel.from_settings({'surface.centers': [0.0], 'surface.widths': [0.5e-3],
                                       'surface.thickness': THICKNESS, 'stroke.amplitude': 8e-6,
                                       'stroke.frequency': 300.0, 'stroke.count': 3, 'particle.x0': x0})
    result = model.run(output_step=2e-5)
    assert result.summary()['transitions'] == {'stick_to_slip': 0, 'slip_to_stick': 0, 'take_off': 0, 'landing': 0}
    table = waveform_table(StrokeParams(amplitude=8e-6, frequency=300.0, count=3), 1)
    values = np.stack([table.evaluate(t)[:2, 0] for t in result['t']])      # s, ṡ
    w = 0.5e-3
    bump_slope = -x0 / w ** 2 * math.exp(-0.5 * (x0 / w) ** 2)              # g'(X)
    want_x = x0 - 0.5 * THICKNESS * values[:, 0] * bump_slope
    want_xdot = -0.5 * THICKNESS * values[:, 1] * bump_slope
    travel = np.ptp(want_x)
    assert travel > 1e-7                                     # it does move: ~0.2 µm back and forth
    np.testing.assert_allclose(result['x'], want_x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result['xdot'], want_xdot, rtol=0, atol=1e-9 * np.abs(want_xdot).max() + 1e-12)
    without = FeederModel.from_settings({'surface.centers': [0.0], 'surface.widths': [0.5e-3],
                                         'stroke.amplitude': 8e-6, 'stroke.frequency': 300.0, 'stroke.count': 3,
                                         'particle.x0': x0}).run(output_step=2e-5)
    assert np.ptp(without['x']) == 0.0                       # the seed's surface: a stuck part stays put


@pytest.mark.parametrize('setting,name', [({'piezo.enabled': True}, 'piezo.enabled'),
                                          ({'integration.friction_logic': 'threshold'}, 'integration.friction_logic'),
                                          ({'particle.x0': [0.0, 3e-4]}, 'particle.x0'),
                                          ({'surface.kind': 'track'}, 'surface.thickness')])
def test_combinations_not_modelled_are_refused_by_name(setting: dict, name: str) -> None:
    with pytest.raises(ParameterError) as err:
        FeederModel.from_settings({'surface.thickness': 1e-3, **setting})
    assert err.value.name == name
