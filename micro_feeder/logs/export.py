"""CSV export: one file per topic, one row per message, one column per scalar field.

Nested fields are flattened with dots (``pose.position.x``), sequences with indices
(``position.0``); the columns of a topic are the union over its messages, in the order they first
appear, so variable-length arrays fit. The first columns are ``log_time_ns`` (receive time) and
``stamp_ns`` (the ``header.stamp`` of stamped types, empty for others; not the MCAP publish time, which
recorders fill differently). Messages that do not decode are skipped and reported by the reader.

One pass over the log, in bounded memory: each row is written at once to a spool file next to its CSV
with the columns known so far (a prefix of the final ones); at the end each CSV is its header then its
spool, rows widened to the final columns where a topic gained columns after its first row.
"""

from __future__ import annotations

import csv
import shutil
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


SPOOL_SUFFIX = '.part'


def export_csv(log: LogReader, directory: Path | str, topics: list[str] | None = None, *,
               progress: Callable[[int, int], None] | None = None) -> list[Path]:
    """Write one CSV per topic into ``directory``; returns the files written. ``progress(done, total)``
    is called every 1000 messages."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    names = list(log.topics) if topics is None else [r for r in map(log.resolve, topics) if r]
    paths = {name: directory / file_name(name) for name in names}
    spools = {name: path.with_name(path.name + SPOOL_SUFFIX) for name, path in paths.items()}
    columns: dict[str, dict[str, None]] = {name: {'log_time_ns': None, 'stamp_ns': None} for name in names}
    first_width: dict[str, int] = {}     # columns when a topic's first row was written
    total = sum(log.topics[name].count for name in names)
    done = 0
    streams = {}
    try:
        streams = {name: open(spool, 'w', newline='') for name, spool in spools.items()}  # noqa: SIM115
        writers = {name: csv.writer(stream) for name, stream in streams.items()}
        for m in log.messages(names, decoded=True):
            row = {'log_time_ns': m.log_time_ns, 'stamp_ns': m.stamp_ns, **flatten(m.message)}
            known = columns[m.topic]
            known.update(dict.fromkeys(row))
            first_width.setdefault(m.topic, len(known))
            writers[m.topic].writerow([row.get(column, '') for column in known])
            done += 1
            if progress is not None and not done % 1000:
                progress(done, total)
        for stream in streams.values():
            stream.close()
        for name in names:
            _finish(paths[name], spools[name], list(columns[name]), first_width.get(name, 2))
    finally:
        for stream in streams.values():
            stream.close()
        for spool in spools.values():
            spool.unlink(missing_ok=True)
    return [paths[name] for name in names]


def _finish(path: Path, spool: Path, columns: list[str], first_width: int) -> None:
    """The CSV: the header, then the spooled rows (widened with empty fields where the topic gained
    columns after its first row)."""
    with open(path, 'w', newline='') as out:
        csv.writer(out).writerow(columns)
        with open(spool, newline='') as rows:
            if first_width == len(columns):      # no column added after the first row: every row is whole
                shutil.copyfileobj(rows, out)
                return
            writer = csv.writer(out)
            for row in csv.reader(rows):
                writer.writerow(row + [''] * (len(columns) - len(row)))
