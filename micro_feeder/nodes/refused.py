"""Publishes the middleware refused, counted instead of ending the node.

A reliable writer adds each sample to its history before sending it. When the history is full, Fast DDS
removes the oldest sample to make room, and it waits up to its ``max_blocking_time`` (100 ms) for the writer.
If that wait times out, ``publish`` raises ``RCLError: cannot publish data``. This happens on a loaded machine
when a subscriber that was stopped (SIGSTOP, a debugger) resumes and asks for repairs. The sample is then in
no subscriber's hands. That is a loss to report, not a reason to end a simulation that every other subscriber
is following.
"""

from __future__ import annotations

import threading
from collections import Counter
from typing import Any

from rclpy._rclpy_pybind11 import RCLError


class RefusedPublishes:
    """Publishes through :meth:`publish`: a refusal is counted per topic (absolute names; :meth:`counts`) and
    logged on ``logger`` (throttled: one line per 10 s at most). The simulator publishes on its loop's
    publishing thread and reports on the executor's, so the counts are kept under a lock."""

    def __init__(self, logger: Any) -> None:
        self._counts: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._logger = logger

    def publish(self, publisher: Any, message: Any) -> bool:
        """``publisher.publish(message)``; False if the middleware refused it (counted and logged)."""
        try:
            publisher.publish(message)
        except RCLError as err:
            with self._lock:
                self._counts[publisher.topic_name] += 1
                total = self._counts.total()
            self._logger.warning(f'the middleware refused a message on {publisher.topic_name} (no subscriber got '
                                 f'it; {total} refused since start): {err}', throttle_duration_sec=10.0)
            return False
        return True

    def counts(self) -> dict[str, int]:
        """Refusals since start, per topic (a copy)."""
        with self._lock:
            return dict(self._counts)

    def total(self) -> int:
        """Refusals since start, on every topic."""
        with self._lock:
            return self._counts.total()
