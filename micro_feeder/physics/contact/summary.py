"""The headline numbers of a contact model at the part's weight (``micro-feeder contact``)."""

from __future__ import annotations

from typing import Any

from .model import ContactModel

# DMT-type adhesion (CEB, KE) assumes a Tabor parameter well below 1; above this the contact is in the
# DMT-JKR transition and the model's adhesion is outside its validity.
DMT_TABOR_LIMIT = 0.1


def headline(model: ContactModel) -> dict[str, Any]:
    """Separation, forces and friction at the weight load, pull-off, and the implied surface geometry.

    Keys carry their SI unit as a suffix (``_m``, ``_n``, ``_mps2``, ``_per_m2``).
    """
    weight = model.weight_n
    d_weight = float(model.separation_at_load(weight))
    at_weight = model.curve(d_weight)
    q_max = float(at_weight.q_max_n[0])
    return {
        'preset': model.contact.preset,
        'weight_n': weight,
        'd_weight_m': d_weight,
        'd_zero_load_m': float(model.separation_at_load(0.0)),
        'contact_load_weight_n': float(at_weight.contact_load_n[0]),
        'adhesion_weight_n': float(at_weight.adhesion_n[0]),
        'q_max_weight_n': q_max,
        'sliding_accel_mps2': q_max / model.particle.mass,
        'mu_weight': q_max / weight,
        'pull_off_n': model.pull_off_n,
        'd_pull_off_m': model.d_pull_off_m,
        'critical_interference_m': model.critical_interference_m,
        'asperity_radius_m': model.asperity_radius_m,
        'asperity_density_per_m2': model.asperity_density_per_m2,
        'asperity_count': model.asperity_count,
        'tabor_parameter': model.tabor_parameter,
        'dmt_valid': model.tabor_parameter < DMT_TABOR_LIMIT,
    }
