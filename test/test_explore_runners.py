"""Local runners: results in order with a bounded window, and a worker that dies mid-run costs only the
tasks in flight (the pool is rebuilt, they are resubmitted); one that keeps dying is an error."""

from __future__ import annotations

import itertools
import os
from pathlib import Path

import pytest

from micro_feeder.explore.runners import InProcess, LocalProcesses, RunnerError


def square_or_die(marker: Path, item: int) -> int:
    """Squares ``item``; the first call with item 5 kills its worker process (once: a marker file)."""
    if item == 5 and not marker.exists():
        marker.touch()
        os._exit(1)
    return item * item


def always_die(item: int) -> int:
    os._exit(1)


def test_results_come_in_order_and_the_input_is_consumed_lazily() -> None:
    consumed = []

    def items():
        for i in itertools.count():
            consumed.append(i)
            yield i

    with LocalProcesses(2, window=3) as runner:
        results = runner.imap(pow, items(), 2)   # pow(2, i)
        assert [next(results) for _ in range(10)] == [2 ** i for i in range(10)]
    assert len(consumed) <= 10 + 3                      # never more than the window ahead


def test_a_dead_worker_costs_only_its_tasks(tmp_path) -> None:
    marker = tmp_path / 'died'
    with LocalProcesses(2, window=4) as runner:
        assert runner.map(square_or_die, range(20), marker) == [i * i for i in range(20)]
    assert marker.exists()                              # a worker did die
    assert InProcess().map(square_or_die, range(4), marker) == [0, 1, 4, 9]


def test_workers_that_keep_dying_are_an_error() -> None:
    with LocalProcesses(2) as runner, pytest.raises(RunnerError, match='keep dying'):
        runner.map(always_die, range(4))
