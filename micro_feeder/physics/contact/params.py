"""Inputs of the Kogut–Etsion rough-surface contact model, with the named presets.

See docs/contact.md §1 (symbols), §5 (choices) and §6 (presets). SI units.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..parameters import ParameterError, ParameterGroup, param

FRICTION_LAWS = ('ke', 'elastic_only', 'linear_to_6')
CONTACT_LAWS = ('ke', 'coulomb')

# What each preset sets (docs/contact.md §6). Fields not listed take the seed's Table 1 defaults.
PRESETS: dict[str, dict[str, Any]] = {
    'seed_paper': {
        'beta': 0.099962, 'epsilon': 0.4e-9, 'adhesion_contact_scale': 0.36037,
        'friction_scale': 0.010814, 'friction_law': 'ke',
    },
    'ke_literature': {
        'beta': 0.04, 'epsilon': 0.4e-9, 'adhesion_contact_scale': 1.0,
        'friction_scale': 1.0, 'friction_law': 'ke',
    },
}


@dataclass(frozen=True)
class ContactParams(ParameterGroup):
    """Rough-surface contact inputs. Defaults are the ``seed_paper`` preset on the seed's Table 1."""

    prefix = 'contact'

    model: str = param('ke', "'ke': rough-surface adhesion and load-dependent friction (the seed's Kogut-Etsion "
                       "model, the other contact.* parameters); 'coulomb': Q_max = mu max(N, 0), no adhesion",
                       choices=CONTACT_LAWS)
    mu: float = param(0.5, "friction coefficient of contact.model 'coulomb', and of landing.law 'coulomb'", '',
                      ge=0.0, le=1e6)
    preset: str = param('seed_paper', 'named parameter set applied before explicit values',
                        choices=tuple(PRESETS))
    sigma: float = param(20e-9, 'standard deviation of the asperity summit heights', 'm', gt=0)
    psi: float = param(2.5, 'plasticity index (2E/(pi K H)) sqrt(sigma/R)', '', gt=0)
    hardness: float = param(1e9, 'hardness H of the softer material', 'Pa', gt=0)
    poisson: float = param(0.33, "Poisson's ratio", '', ge=0, lt=0.5)
    delta_gamma: float = param(1.0, 'work of adhesion (surface-energy difference); > 0 so a pull-off force exists',
                               'J/m^2', gt=0)
    beta: float = param(0.099962, 'roughness parameter eta R sigma', '', gt=0)
    epsilon: float = param(0.4e-9, 'Lennard-Jones equilibrium (intermolecular) distance', 'm', gt=0)
    adhesion_contact_scale: float = param(0.36037, 'multiplier on the contacting-asperity adhesion', '',
                                          ge=0)
    friction_scale: float = param(0.010814, 'multiplier on the maximum static friction Q_max', '', ge=0)
    friction_law: str = param('ke', 'single-asperity sliding-inception law Q_max/L_c',
                              choices=FRICTION_LAWS)
    elastic_modulus: float = param(112.2e9, 'Hertz effective modulus E (reporting only: R, eta, Tabor)',
                                   'Pa', gt=0)

    @classmethod
    def from_flat(cls, values: Mapping[str, Any]) -> ContactParams:
        """Apply ``contact.preset`` first, then every explicitly given ``contact.*`` value."""
        preset = values.get('contact.preset', cls.preset)
        if preset not in PRESETS:
            raise ParameterError('contact.preset', preset, 'one of ' + ', '.join(map(repr, PRESETS)))
        kwargs = dict(PRESETS[preset], preset=preset)
        kwargs.update({f.name: values[name] for f, name, _ in cls.specs() if name in values})
        return cls(**kwargs)

    @classmethod
    def preset_values(cls, name: str) -> ContactParams:
        """The named preset with every other field at its default."""
        return cls.from_flat({'contact.preset': name})
