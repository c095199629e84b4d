"""Opening a log for the log commands: a missing or unreadable log is a user-facing error; a truncated or
damaged one is read as far as it is readable (the reader's warnings go to stderr as ``warning: ...``
lines, see ``cli.main``), and :func:`report_loss` ends the command with what was lost."""

from __future__ import annotations

import sys
from pathlib import Path

from ..logs.reader import LogFormatError, LogReader
from ..progress import Progress
from . import CommandError


def open_log(path: str, command: str = '') -> LogReader:
    """The log at ``path`` (directory or ``.mcap``); CommandError when it is not a log or nothing in it is
    readable. With ``command`` (its name), a progress line goes to stderr while the opening reads a long
    log through (its CRC check, or the scan of a file without summary)."""
    progress = Progress(f'{command}: opening the log', 0, 'MiB') if command else None
    try:
        log = LogReader(Path(path), None if progress is None else lambda done, total: progress(done >> 20, total >> 20))
    except (OSError, LogFormatError) as err:
        raise CommandError(str(err)) from None
    finally:
        if progress is not None:
            progress.close()
    if not log.message_count and log.damage:
        raise CommandError(f'nothing readable in {path}: {log.damage_report()}')
    return log


def report_loss(log: LogReader) -> None:
    """One stderr line saying what the damage found in ``log`` cost (nothing when it has none)."""
    report = log.damage_report()
    if report:
        print(f'warning: {log.path}: {report} (the rest was read)', file=sys.stderr)
