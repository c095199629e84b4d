"""A whole command sent again until the simulator's receipt names it.

Discovery matches a publisher with a new subscriber in two halves: the publisher can see the simulator's
subscription matched while the simulator has not yet matched the publisher, and a volatile message sent in
between is lost without an error on either side. The simulator acknowledges every command it receives on
``simulator/command_receipts`` (``frame_id`` = topic ``#`` identity) and applies an identity once, refusing
copies as duplicates (counted in its ``commands_repeated``, not as faults): so a sender keeps what it sent
until a receipt names it, and sends the same bytes again while none does.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rclpy.clock import Clock, ClockType
from std_msgs.msg import Header

from ..interface.names import split_receipt_frame
from ._ros import topic_qos

RECEIPT_WAIT_S = 1.0        # s a command waits for its receipt before it is sent again
RECEIPT_WAIT_MAX_S = 8.0    # s: the wait doubles after each resend, up to this
CHECK_PERIOD_S = 0.25       # s between looks for a command overdue


@dataclass
class _Awaited:
    command_id: str
    message: bytes
    wait_s: float
    resend_at: float        # monotonic time (s)


class UntilReceipt:
    """At most one command of ``node`` (the latest whole burst) awaiting its receipt: :meth:`expect` it before
    publishing, and it is sent again through ``publish`` (bytes -> False when the middleware refused them)
    every :data:`RECEIPT_WAIT_S`, doubling up to :data:`RECEIPT_WAIT_MAX_S`, while ``reached()`` (a simulator
    is matched) and no receipt names it. A refusal of it by the simulator settles it too (:meth:`settle`): a
    duplicate was applied before, and any other refusal would come again."""

    def __init__(self, node: Any, publish: Callable[[bytes], bool], reached: Callable[[], bool],
                 clock: Callable[[], float] = time.monotonic):
        self._node, self._publish, self._reached, self._clock = node, publish, reached, clock
        self._awaited: _Awaited | None = None
        self.resent = 0             # copies sent, since start
        node.create_subscription(Header, 'simulator/command_receipts', self._on_receipt,
                                 topic_qos('simulator/command_receipts'))
        # wall time: under use_sim_time a sim-time timer would wait for the very sim time a lost command holds
        node.create_timer(CHECK_PERIOD_S, self._check, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @property
    def awaited(self) -> str | None:
        """The identity of the command awaiting its receipt, if one is."""
        awaited = self._awaited
        return None if awaited is None else awaited.command_id

    def expect(self, command_id: str, message: bytes) -> None:
        """``message`` (identity ``command_id``) is about to be sent: keep it until its receipt (it replaces
        any command awaited before)."""
        self._awaited = _Awaited(command_id, message, RECEIPT_WAIT_S, self._clock() + RECEIPT_WAIT_S)

    def settle(self, command_id: str | None = None) -> None:
        """Stop awaiting ``command_id`` (any command, when None): received, refused, or replaced (a stop)."""
        awaited = self._awaited
        if awaited is not None and command_id in (None, awaited.command_id):
            self._awaited = None

    def _on_receipt(self, msg: Header) -> None:
        self.settle(split_receipt_frame(msg.frame_id)[1])

    def _check(self) -> None:
        awaited = self._awaited
        if awaited is None or self._clock() < awaited.resend_at or not self._reached():
            return
        if self._publish(awaited.message):
            self.resent += 1
            self._node.get_logger().info(f'no receipt for {awaited.command_id} after {awaited.wait_s:g} s (a '
                                         'message lost in discovery): sent again')
        awaited.wait_s = min(2.0 * awaited.wait_s, RECEIPT_WAIT_MAX_S)
        awaited.resend_at = self._clock() + awaited.wait_s
