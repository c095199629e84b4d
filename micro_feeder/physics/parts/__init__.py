"""Many parts on one feeder: impacts between neighbours as events, trains of parts pressed together
(docs/parts.md). See :mod:`.model`."""

from .impacts import common_velocity, newton_impact, packed_positions
from .model import Impact, PartsModel, PartsResult, PartsState

__all__ = ['Impact', 'PartsModel', 'PartsResult', 'PartsState', 'common_velocity', 'newton_impact',
           'packed_positions']
