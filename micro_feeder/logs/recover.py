"""Recovering a log whose writer was killed: rewrite every whole chunk's messages into a valid log."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

from .reader import LogReader, TruncatedLogWarning
from .writer import LogWriter


@dataclass
class Recovery:
    """What :func:`recover` did: files that were truncated, messages written, output path."""

    truncated: list[Path]
    messages: int
    output: Path


def recover(source: Path | str, output: Path | str) -> Recovery:
    """Read ``source`` (directory, ``.mcap``, truncated or not) and write its readable messages, with
    their topics, types, offered QoS and times, to ``output`` (a directory, or a ``.mcap`` file)."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', TruncatedLogWarning)
        log = LogReader(source)
    writer = LogWriter(output, flush_period=float('inf'))
    try:
        for topic in log.topics.values():
            writer.add_topic(topic.name, topic.type, topic.metadata.get('offered_qos_profiles', ''))
        writer.custom_data.update(log.recorder_info)
        for m in log.messages():
            writer.write(m.topic, m.data, m.log_time_ns, m.publish_time_ns)
    finally:
        writer.close()
    return Recovery(log.truncated, writer.message_count, writer.path)
