"""The ``simulator`` node's parameters: the model's (the physics groups of ``config/feeder.yaml``, applied on
``~/reset``) and the node's own (:data:`NODE_SPECS`, applied at once by the node's post-set callback), declared
from one table and checked when set, and the ``~/parameters`` event that tells a log which were in force.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterEvent, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..interface import stamps
from ..physics.parameters import ParamSpec
from ..settings import model_specs
from .parameters import check_changes, declare, values

NODE_SPECS: dict[str, tuple[ParamSpec, Any]] = {
    'publish_rate': (ParamSpec('rate of the loop timer and of the state topics', 'Hz', gt=0, le=10000,
                               read_only=True), 1000.0),
    'real_time_factor': (ParamSpec('sim seconds per wall second; 0 = as fast as possible', '', ge=0, le=1000),
                         1.0),
    'start_paused': (ParamSpec('start paused: advance with ~/step, run with ~/pause false',
                               kind='bool', read_only=True), False),
    'publish_clock': (ParamSpec('publish sim time on /clock (default: true in the root namespace, false in '
                                'any other, so that namespaced feeders do not fight over one /clock)',
                                kind='bool', read_only=True), True),
    'step_period': (ParamSpec('sim time advanced by one ~/step call, and per step when '
                              'real_time_factor is 0', 's', gt=0, le=1.0), 1e-3),
    'markers_rate': (ParamSpec('rate of surface/markers (wall clock)', 'Hz', gt=0, le=1000, read_only=True),
                     30.0),
    'lockstep': (ParamSpec('sim time never advances on the wall clock: one step_period per ~/step '
                           'call and per command message received', kind='bool', read_only=True), False),
    'max_command_bytes': (ParamSpec('largest command message accepted (serialized size); a larger one is '
                                    'refused unparsed: send long strokes in windows', 'B', ge=1024, le=2 ** 30,
                                    kind='int', read_only=True), 2 ** 20),
    'publish_thread': (ParamSpec('publish each tick\'s state on a thread of its own, overlapping the next '
                                 'tick\'s integration (micro-feeder run turns it off: its other nodes share '
                                 'the process)', kind='bool', read_only=True), True),
}


class SimulatorParameters:
    """The parameters of the simulator ``node``, declared with ``overrides`` winning over ``--ros-args`` and
    the defaults (a refused value raises :class:`~micro_feeder.physics.parameters.ParameterError`). A later set
    is checked by the on-set callback (a refused set changes nothing). ``applied``: the model's parameters as
    last applied (at start, then by each reset); ``pending``: a model parameter changed since."""

    def __init__(self, node: Node, overrides: Mapping[str, Any] | None = None):
        self._node = node
        self.model_specs = model_specs()
        # One /clock per graph by default: only a simulator in the root namespace publishes it.
        clock_spec = (NODE_SPECS['publish_clock'][0], node.get_namespace() == '/')
        self.specs = {**self.model_specs, **NODE_SPECS, 'publish_clock': clock_spec}
        declare(node, self.specs, overrides)
        self.applied = self.messages(self.model_specs)
        self.pending = False
        node.add_on_set_parameters_callback(self._validate)

    def model(self) -> dict[str, Any]:
        """The model parameters set now (flat ``{dotted name: value}``), applied or not."""
        return values(self._node, self.model_specs)

    def messages(self, names: Iterable[str]) -> list[ParameterMsg]:
        return [self._node.get_parameter(name).to_parameter_msg() for name in names]

    def _validate(self, params: list[Parameter]) -> SetParametersResult:
        """On-set callback: only checks (a refused set changes nothing); the node's post-set callback applies."""
        reason = check_changes(self.specs, self.model(), params)
        return SetParametersResult(successful=reason is None, reason=reason or '')

    def event(self, t: float, started_at_ns: int) -> ParameterEvent:
        """The parameters in force for ``~/parameters``, stamped with the sim time ``t`` (s): the model's as
        last applied (not a change waiting for reset), the node's current ones and ``started_at_ns`` (the
        node's start, wall clock: tells a simulator from a twin of its name)."""
        return ParameterEvent(stamp=stamps.to_time(t), node=self._node.get_fully_qualified_name(),
                              new_parameters=[*self.applied, *self.messages(NODE_SPECS),
                                              Parameter('started_at_ns', value=started_at_ns).to_parameter_msg()])
