"""Single-asperity laws and rough-surface integrals against closed forms and adaptive quadrature."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from micro_feeder.physics.contact import asperity
from micro_feeder.physics.contact.rough_surface import DimensionlessInputs, surface_forces

K = asperity.hardness_coefficient(0.33)


def phi(z: float) -> float:
    return math.exp(-z * z / 2) / math.sqrt(2 * math.pi)


def inputs(law: str = 'ke', omega_c: float = 0.16, beta: float = 0.1) -> DimensionlessInputs:
    return DimensionlessInputs(beta=beta, omega_c=omega_c, epsilon=0.02, hardness_coeff=K, adhesion=0.05,
                               adhesion_contact_scale=0.7, friction_scale=1.0, friction_law=law)


def test_critical_load_identity():
    """P_c = (2/3) pi K H R omega_c equals the Hertz load (4/3) E R^1/2 omega_c^3/2 at omega_c."""
    hardness, modulus, radius = 1e9, 112.2e9, 47e-6
    omega_c = (math.pi * K * hardness / (2 * modulus)) ** 2 * radius
    assert (2 / 3) * math.pi * K * hardness * radius * omega_c == pytest.approx(
        (4 / 3) * modulus * math.sqrt(radius) * omega_c ** 1.5, rel=1e-12)


def test_ke02_fits_jump_as_published():
    """KE02's fits are discontinuous: 13.23 -> 13.46 at w = 6 and 530 -> 560 at w = 110 (K = 0.589)."""
    below, above = asperity.contact_load_ratio(np.array([6.0, 6.0 + 1e-12]), K)
    assert below == pytest.approx(1.03 * 6 ** 1.425) and below == pytest.approx(13.23, abs=0.01)
    assert above == pytest.approx(13.46, abs=0.01)
    below, above = asperity.contact_load_ratio(np.array([110.0, 110.0 + 1e-12]), K)
    assert below == pytest.approx(530, rel=2e-3)
    assert above == pytest.approx(3 / K * 110, rel=1e-9) and above == pytest.approx(560, rel=2e-3)
    assert asperity.contact_load_ratio(np.array([1.0]), K)[0] == pytest.approx(1.0)


def test_bradley_limit_and_lennard_jones_integral():
    """Eq. 8 is 2 pi R times the integral of the LJ pressure (eq. 7), and 2 pi dgamma R at contact."""
    eps = 0.4e-9

    def pressure_times_eps(u):  # eq. 7 with dgamma = 1 at Z = u eps, times dZ/du = eps
        return 8 / 3 * (u ** -3 - u ** -9)

    assert asperity.noncontacting_adhesion_ratio(np.array([0.0]))[0] == pytest.approx(1.0, rel=1e-15)
    assert quad(pressure_times_eps, 1.0, np.inf)[0] == pytest.approx(1.0, rel=1e-9)
    for gap in (0.0, 0.1e-9, 1e-9, 20e-9):
        integral = quad(pressure_times_eps, 1 + gap / eps, np.inf, epsabs=0, epsrel=1e-12)[0]
        assert asperity.noncontacting_adhesion_ratio(np.array([gap / eps]))[0] == pytest.approx(
            integral, rel=1e-9)
    # the contacting (Hertz-DMT) asperity is continuous with it at zero interference
    assert asperity.hertz_dmt_adhesion(np.array([0.0]))[0] == 1.0


@pytest.mark.parametrize(('s', 'expected'), [(1.0, 1.180), (10.0, 1.831), (100.0, 3.560), (1000.0, 7.49)])
def test_hertz_dmt_adhesion_values(s, expected):
    """f(s) of eq. 10 against the values in docs/contact.md §2 and an adaptive quadrature."""

    def integrand(t):
        g = t - (1 - t * t) * math.atan(t)
        x = 1 + s / math.pi * g
        return (x ** -3 - x ** -9) * t

    reference = 8 / 3 * s * quad(integrand, 0, np.inf, limit=500, epsabs=0, epsrel=1e-12)[0]
    assert asperity.hertz_dmt_adhesion(np.array([s]))[0] == pytest.approx(reference, rel=1e-8)
    assert reference == pytest.approx(expected, abs=0.006)


def test_ke_friction_law_shape():
    """q(1) continuous with 0.52 (0.53), maximum ~0.9 near w = 2.5-3, zero at w_lim = 4.295."""
    assert asperity.ke_limiting_interference() == pytest.approx(4.295, abs=5e-4)
    assert asperity.sliding_inception_ratio(np.array([1.0]), 'ke')[0] == pytest.approx(0.52)
    w = np.linspace(1.0 + 1e-12, 4.295, 2000)
    q = asperity.sliding_inception_ratio(w, 'ke')
    assert q[0] == pytest.approx(0.53, abs=1e-9)
    assert q.max() == pytest.approx(0.9, abs=0.05) and 2.3 < w[q.argmax()] < 3.0
    assert asperity.sliding_inception_ratio(np.array([4.3, 10.0]), 'ke').tolist() == [0.0, 0.0]
    assert asperity.sliding_inception_ratio(np.array([1.5]), 'elastic_only')[0] == 0.0
    assert asperity.sliding_inception_ratio(np.array([3.5]), 'linear_to_6')[0] == pytest.approx(0.26)


def test_elastic_gw_limit():
    """With every summit elastic (huge omega_c), P* reduces to GW's F_3/2(h):
    F_3/2(0) = 0.4300, F_3/2(2) = 6.648e-3, F_3/2(3) = 2.640e-4."""
    omega_c = 400.0
    inp = inputs(omega_c=omega_c)
    prefactor = (2 / 3) * math.pi * K * inp.beta * omega_c * omega_c ** -1.5
    gw = surface_forces(np.array([0.0, 2.0, 3.0]), inp).contact_load / prefactor
    np.testing.assert_allclose(gw, [0.4300, 6.648e-3, 2.640e-4], rtol=2e-4)


@pytest.mark.parametrize('law', ['ke', 'elastic_only', 'linear_to_6'])
@pytest.mark.parametrize('d', [-1.5, 0.0, 2.0, 3.77, 4.28, 7.0, 30.0, 80.0])
def test_integrals_match_adaptive_quadrature(law, d):
    """P*, F_s* (non-contacting to 1e-8, contacting to 1e-7) and Q_max* against scipy.integrate.quad
    on the defining integrals (eqs. 6, 11, 13), using only the single-asperity laws."""
    inp = inputs(law)
    wc = inp.omega_c
    kinks = [d + wc * k for k in (1.0, asperity.ke_limiting_interference(), 6.0, 110.0)]
    top = 40.0

    def over_contacts(law_of_w, stops=kinks):
        if d >= top:
            return 0.0
        pts = [p for p in stops if d < p < top]
        return quad(lambda z: float(law_of_w(np.array((z - d) / wc))) * phi(z), d, top, points=pts or None,
                    limit=800, epsabs=0, epsrel=1e-12)[0]

    def noncontact():
        lo = -40.0
        pts = [p for p in (d - inp.epsilon, d - 10 * inp.epsilon, d - 1.0) if lo < p < d]
        return quad(lambda z: float(asperity.noncontacting_adhesion_ratio(np.array((d - z) / inp.epsilon))) * phi(z),
                    lo, d, points=pts or None, limit=800, epsabs=0, epsrel=1e-12)[0]

    load_pre = (2 / 3) * math.pi * K * inp.beta * wc
    adh_pre = 2 * math.pi * inp.beta * inp.adhesion
    forces = surface_forces(np.array([d]), inp)
    ref_p = load_pre * over_contacts(lambda w: asperity.contact_load_ratio(w, K))
    ref_q = load_pre * over_contacts(lambda w: asperity.sliding_inception_ratio(w, law))
    ref_nc = adh_pre * noncontact()
    ref_c = adh_pre * over_contacts(lambda w: asperity.contacting_adhesion_ratio(w, wc / inp.epsilon, 0.7))
    assert forces.contact_load[0] == pytest.approx(ref_p, rel=1e-8, abs=1e-300)
    assert forces.q_max[0] == pytest.approx(ref_q, rel=1e-8, abs=1e-300)
    assert forces.adhesion_noncontact[0] == pytest.approx(ref_nc, rel=1e-8)
    assert forces.adhesion_contact[0] == pytest.approx(ref_c, rel=1e-7, abs=1e-300)


def test_separation_below_every_summit():
    """d* below -Z_CUTOFF: every summit touches, so no non-contacting adhesion, and the contact load is the
    fully plastic mean (3/K) E[w] = (3/K)(0 - d*)/omega_c* times the load prefactor."""
    inp = inputs()
    d = np.array([-40.0, -45.0])
    forces = surface_forces(d, inp)
    assert np.all(forces.adhesion_noncontact == 0.0)
    prefactor = (2 / 3) * math.pi * K * inp.beta * inp.omega_c
    np.testing.assert_allclose(forces.contact_load, prefactor * (3 / K) * (-d) / inp.omega_c, rtol=1e-9)
