"""Whether the process named by a device lock (``{"pid", "host", "since"}``) is still running.

A device's lock (:func:`stickslip.procedures.move.device_lock`) names its holder by
process id, host and the time it was taken. On this host a holder that is gone is taken
over without asking (:func:`process_gone`). A process number is reused, though (after a
restart the numbers begin again), so a number that is running may be another program's:
:func:`holder_running` says a holder runs only when Linux's start time of the process is
no later than the lock (elsewhere, or with a later start, it cannot tell).

A later start is not taken as proof the holder is gone (the lock is not taken over on
it): a wall clock stepped forward while the holder runs (a laptop woken, NTP) makes a
holder seem to have started after its own lock.
"""

from __future__ import annotations

import datetime as _dt
import os
import socket
from typing import Any

__all__ = ["holder_running", "process_gone"]

START_SLACK_S = 5.0
"""s: how much later than the lock's ``since`` its holder may seem to have started and still be known to run.

``since`` is kept to the second, and Linux gives the boot time to the second and a start
in clock ticks: a few seconds cover the rounding; a reused number started later than that.
"""


def process_gone(holder: object) -> bool:
    """Whether ``holder`` names a process of this host that no longer exists (POSIX signal 0; elsewhere never)."""
    pid = _local_pid(holder)
    if pid is None:
        return False
    try:
        os.kill(pid, 0)  # POSIX: signal 0 only checks that the process exists
    except ProcessLookupError:
        return True
    except OSError:
        return False  # it exists, another user's
    return False


def holder_running(holder: object) -> bool:
    """Whether ``holder`` is known to run on this host: its process exists and (Linux) started before the lock.

    ``False`` also when it cannot be told: a holder on another host, one without a process
    number, a host without ``/proc``, or a process that started after the lock was taken
    (its number reused, or the clock stepped).
    """
    pid = _local_pid(holder)
    if pid is None or process_gone(holder) or not isinstance(holder, dict):
        return False
    started, since = _started_at(pid), _since(holder)
    return started is not None and since is not None and started <= since + START_SLACK_S


def _local_pid(holder: object) -> int | None:
    """The process number of a holder on this POSIX host, else ``None``."""
    if not isinstance(holder, dict) or os.name != "posix" or holder.get("host") != socket.gethostname():
        return None
    pid = holder.get("pid")
    if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0:
        return None
    return pid


def _since(holder: dict[str, Any]) -> float | None:
    """The lock's ``since`` as a POSIX time (s), or ``None`` if it is not an ISO time with its zone."""
    text = holder.get("since")
    if not isinstance(text, str):
        return None
    try:
        when = _dt.datetime.fromisoformat(text)
    except ValueError:
        return None
    return None if when.tzinfo is None else when.timestamp()


def _started_at(pid: int) -> float | None:
    """When process ``pid`` started, POSIX time (s), from Linux's ``/proc``; ``None`` elsewhere or unreadable."""
    try:
        with open(f"/proc/{pid}/stat", encoding="utf-8", errors="replace") as f:
            stat = f.read()
        with open("/proc/stat", encoding="utf-8", errors="replace") as f:
            boot = next(int(line.split()[1]) for line in f if line.startswith("btime "))
        ticks = int(stat.rpartition(")")[2].split()[19])  # field 22, starttime: clock ticks after boot
        return boot + ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):
        return None
