"""A disk that fills up, for tests: every file opened for writing through ``os.fdopen`` (the atomic writes) fails
with an errno once more than ``limit`` characters or bytes were written; a real full disk's stream is broken after
that, so a seek fails too."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any


class Filling:
    """A file whose writes fail with ``code`` once ``limit`` characters or bytes were written (``seen`` counts them
    across files and notes ``failed``)."""

    def __init__(self, f: Any, limit: int, code: int, seen: dict[str, Any]) -> None:
        self._f, self._limit, self._code, self._seen = f, limit, code, seen

    def write(self, data: Any) -> Any:
        self._seen["n"] += len(data)
        if self._seen["n"] > self._limit:
            self._seen["failed"] = True
            raise OSError(self._code, os.strerror(self._code))
        return self._f.write(data)

    def seek(self, *a: Any) -> Any:
        if self._seen["failed"]:  # as a real full disk: the stream is broken once a write failed
            raise OSError(self._code, os.strerror(self._code))
        return self._f.seek(*a)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._f, name)

    def __enter__(self) -> Filling:
        return self

    def __exit__(self, *exc: object) -> None:
        self._f.close()


def filling_fdopen(limit: int, code: int, seen: dict[str, Any]) -> Callable[..., Any]:
    """An ``os.fdopen`` whose files opened for writing fill after ``limit`` (``seen``: {"n": 0, "failed": False})."""
    real = os.fdopen

    def fdopen(fd: int, mode: str = "r", *a: Any, **k: Any) -> Any:
        f = real(fd, mode, *a, **k)
        return Filling(f, limit, code, seen) if ("w" in mode or "a" in mode) else f

    return fdopen
