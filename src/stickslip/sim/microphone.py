"""What a microphone beside the simulated arm hears: blocks rendered on the virtual clock
from the arm's step events by the shared :class:`~stickslip.sim.sound.Soundscape`."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from .sound import Soundscape


class SoundingArm(Protocol):
    """What a virtual microphone needs of the arm it listens to (``SimulatedMM3A`` is one)."""

    sample_rate: int
    clock_s: float

    @property
    def soundscape(self) -> Soundscape: ...

    def step_events(
        self, t_from: float, t_to: float
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]]: ...

    def add_listener(self, mic: VirtualMicrophone) -> None:
        """Keep the step events this microphone has not heard yet."""
        ...

__all__ = ["VirtualMicrophone"]


_SCAPES: dict[tuple[object, ...], Soundscape] = {}


def _soundscape(sample_rate: int, seed: int, kwargs: dict[str, Any]) -> Soundscape:
    """A shared :class:`~stickslip.sim.sound.Soundscape` (stateless renders; costly to build)."""
    key = (sample_rate, seed, tuple(sorted((k, repr(v)) for k, v in kwargs.items())))
    scape = _SCAPES.get(key)
    if scape is None:
        if len(_SCAPES) >= 8:
            _SCAPES.pop(next(iter(_SCAPES)))
        scape = _SCAPES[key] = Soundscape(sample_rate=sample_rate, seed=seed, **kwargs)
    return scape


class VirtualMicrophone:
    """What a microphone beside the simulated arm hears, on the virtual clock.

    Blocks are rendered by the simulator's :class:`~stickslip.sim.sound.Soundscape`
    from the recorded step events. The stream starts at the simulator's clock when the
    microphone is made; only complete blocks up to the current clock are available
    (the future has not been stepped yet).

    Use it as a callable (``mic()`` returns the list of blocks recorded since the last
    call: the traverse procedure's ``audio_blocks``) or iterate over it (finite:
    the blocks available now). A ``silent`` microphone gives zeros without rendering
    (for :class:`OracleStopDetector` runs).
    """

    def __init__(self, sim: SoundingArm, block: int = 1024, silent: bool = False):
        if not 16 <= int(block) <= 1 << 20:
            raise ValueError(f"block = {block!r} samples is outside [16, 1048576]")
        self.sim = sim
        self.block = int(block)
        self.sample_rate = sim.sample_rate
        self.silent = bool(silent)
        self._next = int(math.ceil(sim.clock_s * self.sample_rate - 1e-6))
        sim.add_listener(self)  # the arm keeps the step events this microphone still needs

    @property
    def t_s(self) -> float:
        """Stream time of the next sample, s (virtual clock)."""
        return self._next / self.sample_rate

    def _render(self, n: int) -> NDArray[np.float32]:
        if self.silent:
            self._next += n
            return np.zeros(n, dtype=np.float32)
        scape = self.sim.soundscape
        t0 = self.t_s
        t1 = (self._next + n) / self.sample_rate
        tail = float(getattr(scape, "tail_s", 0.1))
        times, joints, stops = self.sim.step_events(t0 - tail, t1)
        out = np.asarray(scape.render(t0, n, times, joints, stops), dtype=np.float32)
        self._next += n
        return out

    def read_until(self, t_s: float) -> NDArray[np.float32]:
        """All samples from the stream position up to time ``t_s`` (s), as one array."""
        n = int(math.floor(t_s * self.sample_rate + 1e-6)) - self._next
        if n <= 0:
            return np.empty(0, dtype=np.float32)
        parts = []
        while n > 0:
            m = min(n, 1 << 18)
            parts.append(self._render(m))
            n -= m
        return np.concatenate(parts)

    def __call__(self) -> list[NDArray[np.float32]]:
        """The complete blocks recorded since the last call (may be empty)."""
        n_avail = int(math.floor(self.sim.clock_s * self.sample_rate + 1e-6)) - self._next
        n_blocks = n_avail // self.block
        if n_blocks <= 0:
            return []
        out: list[NDArray[np.float32]] = []
        per_chunk = max(1, (1 << 17) // self.block)
        while n_blocks > 0:
            m = min(n_blocks, per_chunk)
            chunk = self._render(m * self.block)
            out.extend(chunk[i * self.block : (i + 1) * self.block] for i in range(m))
            n_blocks -= m
        return out

    def __iter__(self) -> Iterator[NDArray[np.float32]]:
        return iter(self())

    def skip_to(self, t_s: float | None = None) -> None:
        """Jump the stream to time ``t_s`` (default: now), dropping the audio in between."""
        t = self.sim.clock_s if t_s is None else float(t_s)
        self._next = max(self._next, int(math.ceil(t * self.sample_rate - 1e-6)))
