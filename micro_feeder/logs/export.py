"""CSV export: one file per topic, one row per message, one column per scalar field.

Nested fields are flattened with dots (``pose.position.x``), sequences with indices
(``position.0``); the columns of a topic are the union over its messages (two passes over the log), so
variable-length arrays fit. The first columns are ``log_time_ns`` (receive time) and ``stamp_ns`` (the
``header.stamp`` of stamped types, empty for others; not the MCAP publish time, which recorders fill
differently). Messages that do not decode are skipped and reported by the reader.
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .reader import LogReader


def flatten(msg: Any, prefix: str = '') -> dict[str, Any]:
    """``{dotted field path: scalar}`` of a decoded message."""
    if isinstance(msg, (list, tuple)):
        out: dict[str, Any] = {}
        for i, item in enumerate(msg):
            out.update(flatten(item, f'{prefix}{i}.'))
        return out
    if isinstance(msg, bytes):
        return {prefix.rstrip('.'): msg.hex()}
    slots = getattr(msg, '__slots__', None)
    if slots is None:
        return {prefix.rstrip('.'): msg}
    out = {}
    for name in slots:
        out.update(flatten(getattr(msg, name), f'{prefix}{name}.'))
    return out


def file_name(topic: str) -> str:
    """``/particle/pose`` -> ``particle__pose.csv``."""
    return topic.strip('/').replace('/', '__') + '.csv'


def export_csv(log: LogReader, directory: Path | str, topics: list[str] | None = None, *,
               progress: Callable[[int, int], None] | None = None) -> list[Path]:
    """Write one CSV per topic into ``directory``; returns the files written. ``progress(done, total)``
    is called every 1000 messages (two passes over the log)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    names = list(log.topics) if topics is None else [r for r in map(log.resolve, topics) if r]
    columns: dict[str, dict[str, None]] = {name: {} for name in names}
    total = 2 * sum(log.topics[name].count for name in names)
    done = 0
    for m in log.messages(names, decoded=True):
        columns[m.topic].update(dict.fromkeys(flatten(m.message)))
        done += 1
        if progress is not None and not done % 1000:
            progress(done, total)
    written = []
    files = {name: open(directory / file_name(name), 'w', newline='') for name in names}  # noqa: SIM115
    try:
        writers = {}
        for name, stream in files.items():
            writers[name] = csv.DictWriter(stream, ['log_time_ns', 'stamp_ns', *columns[name]])
            writers[name].writeheader()
            written.append(Path(stream.name))
        for m in log.messages(names, decoded=True):
            writers[m.topic].writerow({'log_time_ns': m.log_time_ns, 'stamp_ns': m.stamp_ns,
                                       **flatten(m.message)})
            done += 1
            if progress is not None and not done % 1000:
                progress(done, total)
    finally:
        for stream in files.values():
            stream.close()
    return written
