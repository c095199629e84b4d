"""Particle dynamics on the actuated surface (docs/dynamics.md, docs/events.md): modes, events, integrator, stepper API.

See :mod:`.model` for the API; :mod:`.kernel` is the compiled engine.
"""

from .model import EVENT_KINDS, MODES, Event, FeederModel, FeederState, Observation, RunResult, SimulationError
from .params import DetachParams, IntegrationParams, LandingParams

__all__ = ['EVENT_KINDS', 'MODES', 'DetachParams', 'Event', 'FeederModel', 'FeederState', 'IntegrationParams',
           'LandingParams', 'Observation', 'RunResult', 'SimulationError']
