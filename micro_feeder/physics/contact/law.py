"""The contract between a contact law and the dynamics: what the kernel reads of any law.

A law is an object with ``tables`` (:class:`~.model.ContactTables`: Q_max and the separation against the
normal load, the attraction against the gap in flight) and ``pull_off_n`` (N: the part leaves the surface
when the normal load falls below minus this). The dynamics interpolate the tables linearly and extrapolate
Q_max linearly beyond the last load, so a law that is linear in N there is exact. Adding a law is one
module that builds these, and one entry in :func:`contact_law`.
"""

from __future__ import annotations

from typing import Protocol

from ..particle import ParticleParams
from .coulomb import CoulombContact
from .model import ContactModel, ContactTables
from .params import ContactParams


class ContactLaw(Protocol):
    """What the dynamics read of a contact law (see the module docstring)."""

    @property
    def tables(self) -> ContactTables: ...

    @property
    def pull_off_n(self) -> float: ...


def contact_law(contact: ContactParams, particle: ParticleParams) -> ContactLaw:
    """The law ``contact.model`` names: 'ke' (rough-surface adhesion and friction) or 'coulomb'."""
    if contact.model == 'coulomb':
        return CoulombContact(contact.mu)
    return ContactModel(contact, particle)
