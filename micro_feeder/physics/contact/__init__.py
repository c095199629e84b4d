"""Kogut–Etsion rough-surface adhesion and static friction (docs/contact.md).

``ContactModel(ContactParams(...), ParticleParams(...))`` builds the load-indexed tables the dynamics
uses; ``ContactParams.preset_values('ke_literature')`` gives a named preset.
"""

from .model import ContactModel, ContactTables, PulledOffError, SeparationCurve
from .params import FRICTION_LAWS, PRESETS, ContactParams

__all__ = ['FRICTION_LAWS', 'PRESETS', 'ContactModel', 'ContactParams', 'ContactTables', 'PulledOffError',
           'SeparationCurve']
