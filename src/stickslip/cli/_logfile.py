"""The ``--log-file`` handler: a log file that cannot be written is one warning line, not a traceback per record."""

from __future__ import annotations

import logging
import sys

from ._common import describe, warn


class LogFile(logging.FileHandler):
    """A ``FileHandler`` whose first failed write (a full disk, a quota) is one ``warning:`` line; then it stops.

    logging's own handler printed ``--- Logging error ---`` and a traceback on stderr for every
    record it could not write (every message to and from a controller, at DEBUG), while the
    command went on.
    """

    failed = False

    def emit(self, record: logging.LogRecord) -> None:
        if not self.failed:
            super().emit(record)

    def handleError(self, record: logging.LogRecord) -> None:  # noqa: N802 - logging's name
        if self.failed:
            return
        self.failed = True
        e = sys.exc_info()[1]
        why = (e.strerror or str(e)) if isinstance(e, OSError) else describe(e) if e is not None else "unknown"
        warn(f"cannot write the log file {self.baseFilename}: {why}; nothing more is logged to it")
