"""``micro-feeder contact`` end to end, checked against an independent implementation of
docs/contact.md written here with scipy's adaptive quadrature and root finding only."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq, minimize_scalar

CLI = [str(Path(sys.executable).parent / 'micro-feeder')]   # the installed console script


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, 'contact', *args], capture_output=True, text=True, timeout=120)


class IndependentKE:
    """docs/contact.md §2-3 by adaptive quadrature, in SI units."""

    def __init__(self, sigma, psi, hardness, poisson, delta_gamma, beta, epsilon, c_a, q_scale, law,
                 mass, area=1e-8, gravity=9.81):
        self.sigma, self.beta, self.law, self.c_a, self.q_scale = sigma, beta, law, c_a, q_scale
        self.k = 0.454 + 0.41 * poisson
        self.wc = 1 / psi ** 2
        self.eps = epsilon / sigma
        self.adh = delta_gamma / (hardness * sigma)
        self.unit = area * hardness
        self.weight = mass * gravity
        s = np.geomspace(1e-6, 2e3, 300)   # f(s) of eq. 10 tabulated by quad
        self.log_s, self.f = np.log(s), np.array([self._f_quad(v) for v in s])

    @staticmethod
    def _f_quad(s):
        def integrand(rho):
            r = math.sqrt(rho * rho - 1)
            x = 1 + s / math.pi * (r - (2 - rho * rho) * math.atan(r))
            return (x ** -3 - x ** -9) * rho
        return 8 / 3 * s * quad(integrand, 1, np.inf, limit=400)[0]

    def load_law(self, w):
        if w <= 1:
            return w ** 1.5
        if w <= 6:
            return 1.03 * w ** 1.425
        return 1.40 * w ** 1.263 if w <= 110 else 3 / self.k * w

    def friction_law(self, w):
        if w <= 1:
            return 0.52 * w ** 0.982
        if self.law == 'ke':
            return max(w ** 1.425 * (-0.01 * w ** 3 + 0.09 * w ** 2 - 0.40 * w + 0.85), 0.0) if w < 4.3 else 0.0
        if self.law == 'linear_to_6':
            return max(0.52 * (6 - w) / 5, 0.0)
        return 0.0

    def contact_adhesion_law(self, w):
        s = w * self.wc / self.eps
        return self.c_a * (np.interp(math.log(max(s, 1e-6)), self.log_s, self.f) if w <= 110 else 1.0)

    def forces(self, d):
        """(P, F_s, Q_max) in N at separation d (m)."""
        ds = d / self.sigma
        phi = lambda z: math.exp(-z * z / 2) / math.sqrt(2 * math.pi)  # noqa: E731
        pts = [ds + self.wc * k for k in (1, 4.2946, 6, 110)]

        def over_contacts(law):
            return quad(lambda z: law((z - ds) / self.wc) * phi(z), ds, max(ds, 0) + 40, points=pts, limit=400)[0]

        def nc(z):
            r = self.eps / (ds - z + self.eps)
            return 4 / 3 * (r ** 2 - 0.25 * r ** 8) * phi(z)

        noncontact = quad(nc, -40, ds, points=[ds - self.eps, ds - 1], limit=400)[0]
        load_pre = 2 / 3 * math.pi * self.k * self.beta * self.wc * self.unit
        adh_pre = 2 * math.pi * self.beta * self.adh * self.unit
        return (load_pre * over_contacts(self.load_law),
                adh_pre * (noncontact + over_contacts(self.contact_adhesion_law)),
                self.q_scale * load_pre * over_contacts(self.friction_law))

    def applied(self, d):
        p, fs, _ = self.forces(d)
        return p - fs

    def headline(self):
        s = self.sigma
        best = minimize_scalar(self.applied, bounds=(0.0, 10 * s), method='bounded', options={'xatol': 1e-6 * s})
        d_min = best.x
        d_weight = brentq(lambda d: self.applied(d) - self.weight, d_min - 8 * s, d_min, xtol=1e-9 * s)
        return {'d_weight_m': d_weight, 'q_max_weight_n': self.forces(d_weight)[2], 'pull_off_n': -best.fun,
                'd_pull_off_m': d_min}


CASES = {
    'rougher, softer LJ, linear_to_6': (
        ['contact.preset=ke_literature', 'contact.sigma=30e-9', 'contact.psi=1.8', 'contact.epsilon=0.3e-9',
         'contact.friction_law=linear_to_6', 'particle.mass=5e-9'],
        dict(sigma=30e-9, psi=1.8, hardness=1e9, poisson=0.33, delta_gamma=1.0, beta=0.04, epsilon=0.3e-9,
             c_a=1.0, q_scale=1.0, law='linear_to_6', mass=5e-9)),
    'harder, weaker adhesion, elastic_only': (
        ['contact.beta=0.07', 'contact.delta_gamma=0.5', 'contact.hardness=2e9', 'contact.poisson=0.3',
         'contact.adhesion_contact_scale=0.5', 'contact.friction_law=elastic_only', 'contact.psi=3.0'],
        dict(sigma=20e-9, psi=3.0, hardness=2e9, poisson=0.3, delta_gamma=0.5, beta=0.07, epsilon=0.4e-9,
             c_a=0.5, q_scale=0.010814, law='elastic_only', mass=2e-9)),
}


# quad reports roundoff where the 'ke' and 'elastic_only' friction laws are identically zero; harmless here
@pytest.mark.filterwarnings('ignore::scipy.integrate.IntegrationWarning')
@pytest.mark.parametrize('case', list(CASES))
def test_json_agrees_with_independent_implementation(case):
    overrides, inputs = CASES[case]
    result = run_cli('--json', *[a for o in overrides for a in ('--set', o)])
    assert result.returncode == 0, result.stderr
    ours = json.loads(result.stdout)
    reference = IndependentKE(**inputs).headline()
    assert ours['d_weight_m'] == pytest.approx(reference['d_weight_m'], rel=2e-3)
    assert ours['d_pull_off_m'] == pytest.approx(reference['d_pull_off_m'], rel=2e-3)
    assert ours['q_max_weight_n'] == pytest.approx(reference['q_max_weight_n'], rel=1e-2)
    assert ours['pull_off_n'] == pytest.approx(reference['pull_off_n'], rel=1e-2)
    assert ours['sliding_accel_mps2'] == pytest.approx(ours['q_max_weight_n'] / inputs['mass'], rel=1e-12)
    assert ours['mu_weight'] == pytest.approx(ours['q_max_weight_n'] / (inputs['mass'] * 9.81), rel=1e-12)


def test_json_curve_in_given_order_and_nothing_else_on_stdout():
    result = run_cli('--json', '--d-nm', '80,70,75.5')
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)   # the whole of stdout is one JSON object
    assert [row['d_m'] for row in out['curve']] == pytest.approx([80e-9, 70e-9, 75.5e-9])
    for row in out['curve']:
        assert row['applied_load_n'] == pytest.approx(row['contact_load_n'] - row['adhesion_n'], rel=1e-12)
    assert out['curve'][1]['applied_load_n'] > 0 > out['curve'][0]['applied_load_n']


def test_human_table_and_plot(tmp_path):
    png = tmp_path / 'contact.png'
    result = run_cli('--plot', str(png))
    assert result.returncode == 0, result.stderr
    for label in ('separation d at W', 'max static friction', 'pull-off force', 'Tabor parameter',
                  'summits in the nominal area', 'warning: Tabor parameter'):
        assert label in result.stdout
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 20_000


@pytest.mark.parametrize(('override', 'message'), [
    ('contact.psi=0', 'contact.psi = 0 is not allowed: a finite number > 0'),
    ('contact.friction_law=coulomb', "contact.friction_law = 'coulomb' is not allowed: one of 'ke'"),
    ('contact.beta=nan', 'contact.beta = nan is not allowed'),
    ('contact.sigm=2e-8', "unknown parameter 'contact.sigm'; did you mean contact.sigma"),
    ('contact.sigma', 'expects NAME=VALUE'),
    ('contact.beta=1e-4', 'contact.beta = 0.0001 is not allowed: large enough for the surface to carry 1 N'),
])
def test_bad_parameters_exit_2_with_a_reason(override, message):
    result = run_cli('--set', override)
    assert result.returncode == 2
    assert message in result.stderr and result.stdout == ''


def test_params_file_ros_format(tmp_path):
    """A ROS 2 parameters file (the format of config/feeder.yaml) is read by --params."""
    f = tmp_path / 'p.yaml'
    f.write_text('/**:\n  ros__parameters:\n    contact:\n      preset: ke_literature\n    particle:\n'
                 '      mass: 4.0e-9\n')
    result = run_cli('--json', '--params', str(f))
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out['preset'] == 'ke_literature' and out['weight_n'] == pytest.approx(4e-9 * 9.81)
