"""Recovering a log whose writer was killed or whose file was damaged: rewrite every message of every
undamaged chunk into a new, complete log, and say what was dropped and where."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

from .mcap_file import Damage
from .reader import LogFormatError, LogReader, LogWarning
from .writer import LogWriter


@dataclass
class Recovery:
    """What :func:`recover` did: files that were truncated, messages written, output path, the damage
    skipped (each with where and how many messages it cost) and the messages dropped (None: unknown)."""

    truncated: list[Path]
    messages: int
    output: Path
    damage: list[Damage] = field(default_factory=list)
    dropped: int | None = 0


def recover(source: Path | str, output: Path | str) -> Recovery:
    """Read ``source`` (directory, ``.mcap``, truncated, damaged or not) and write its readable messages,
    with their topics, types, offered QoS and times, to ``output`` (a new directory, or a ``.mcap`` file)."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', LogWarning)   # the Recovery lists the damage
        log = LogReader(source)
        if not log.message_count and (log.damage or log.truncated):
            raise LogFormatError(f'nothing readable in {source}: '
                                 f'{log.damage_report() or "truncated before its first whole chunk"}')
        writer = LogWriter(output, flush_period=float('inf'))
        try:
            for topic in log.topics.values():
                writer.add_topic(topic.name, topic.type, topic.metadata.get('offered_qos_profiles', ''))
            writer.custom_data.update(log.recorder_info)
            for m in log.messages():
                writer.write(m.topic, m.data, m.log_time_ns, m.publish_time_ns)
        finally:
            writer.close()
    return Recovery(log.truncated, writer.message_count, writer.path, list(log.damage), log.lost)
