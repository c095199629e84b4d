"""Opening a log for the log commands: a missing or unreadable log is a user-facing error, and a
truncated one is reported on stderr (once) instead of as a Python warning."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from ..logs.reader import LogFormatError, LogReader, TruncatedLogWarning
from . import CommandError


def open_log(path: str) -> LogReader:
    """The log at ``path`` (directory or ``.mcap``); truncation warnings go to stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always', TruncatedLogWarning)
        try:
            log = LogReader(Path(path))
        except (OSError, LogFormatError) as err:
            raise CommandError(str(err)) from None
    for w in caught:
        print(f'warning: {w.message}', file=sys.stderr)
    return log
