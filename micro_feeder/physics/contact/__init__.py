"""Contact laws: Kogut–Etsion rough-surface adhesion and static friction (docs/contact.md), and Coulomb
friction (docs/tracks.md), behind one contract (:mod:`.law`).

``ContactModel(ContactParams(...), ParticleParams(...))`` builds the load-indexed tables the dynamics
uses; ``ContactParams.preset_values('ke_literature')`` gives a named preset.
"""

from .coulomb import CoulombContact
from .law import ContactLaw, contact_law
from .model import ContactModel, ContactTables, PulledOffError, SeparationCurve
from .params import CONTACT_LAWS, FRICTION_LAWS, PRESETS, ContactParams

__all__ = ['CONTACT_LAWS', 'FRICTION_LAWS', 'PRESETS', 'ContactLaw', 'ContactModel', 'ContactParams',
           'ContactTables', 'CoulombContact', 'PulledOffError', 'SeparationCurve', 'contact_law']
