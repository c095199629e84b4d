"""Particle dynamics on the actuated surface (docs/dynamics.md, docs/events.md): modes, events, integrator, stepper API.

See :mod:`.model` for the API; :mod:`.kernel` is the compiled engine.
"""

from .event_list import EVENT_KINDS, MODES, TRANSITION_KINDS, Event, EventList
from .model import FeederModel, FeederState, Observation, RunResult, SimulationError
from .params import DetachParams, IntegrationParams, LandingParams

__all__ = ['EVENT_KINDS', 'MODES', 'TRANSITION_KINDS', 'DetachParams', 'Event', 'EventList', 'FeederModel',
           'FeederState', 'IntegrationParams', 'LandingParams', 'Observation', 'RunResult', 'SimulationError']
