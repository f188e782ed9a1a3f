"""What the simulated MM3A stepped: its bursts, for the virtual microphone and the true stop times."""

from __future__ import annotations

import bisect
import math
import threading
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .microphone import VirtualMicrophone, _soundscape
from .true_steps import joint_number

if TYPE_CHECKING:
    from .sound import Soundscape

__all__ = ["StepLog"]

_KEEP_BURSTS = 4096  # burst records kept before those all microphones have heard are dropped


@dataclass
class _Burst:
    """One burst of steps, for the virtual microphone: steps at ``t0 + k / hz``, k < n."""

    t0: float
    hz: float
    joint: int
    n: int
    k_stop: int  # steps with k >= k_stop began at the end stop (did not move)
    sign: int = 1

    @property
    def t_end(self) -> float:
        return self.t0 + self.n / self.hz



class StepLog:
    """The bursts stepped, heard by virtual microphones: step events, runs against a stop, the soundscape.

    The attributes are set by :class:`~stickslip.sim.arm.SimulatedMM3A`.
    """

    sample_rate: int
    seed: int
    soundscape_kwargs: dict[str, Any]
    clock_s: float
    _lock: threading.RLock
    _bursts: list[_Burst]
    _burst_ends: list[float]
    _runs: dict[int, list[list[float]]]
    _last_burst: dict[int, _Burst | None]
    _mics: weakref.WeakSet[VirtualMicrophone]
    _soundscape: Soundscape | None

    def _log_burst(self, t0: float, hz: float, joint: int, n: int, k_stop: int, sign: int) -> None:
        """Record a burst of ``n`` steps from ``t0`` (s) at ``hz``; the steps from ``k_stop`` on began at the stop."""
        burst = _Burst(t0, hz, joint, n, k_stop, sign)
        self._bursts.append(burst)
        self._burst_ends.append(burst.t_end)
        self._note_stop_run(burst)
        if len(self._bursts) > _KEEP_BURSTS:
            self._forget_heard()

    def _note_stop_run(self, b: _Burst) -> None:
        """Extend or start a run of at-stop steps (see :meth:`stop_runs`)."""
        prev = self._last_burst[b.joint]
        self._last_burst[b.joint] = b
        if b.k_stop >= b.n:
            return
        runs = self._runs[b.joint]
        continued = (
            prev is not None
            and runs
            and b.k_stop == 0
            and prev.sign == b.sign
            and prev.k_stop < prev.n
            and abs(prev.t_end - b.t0) < 0.5 / b.hz
        )
        if continued:
            runs[-1][1] = b.t_end
        else:
            runs.append([b.t0 + b.k_stop / b.hz, b.t_end])

    def _forget_heard(self) -> None:
        """Drop burst records every live microphone has rendered (keeps long sessions lean)."""
        horizon = min((m.t_s for m in list(self._mics)), default=self.clock_s) - 1.0
        k = bisect.bisect_left(self._burst_ends, horizon)
        if k > 0:
            del self._bursts[:k]
            del self._burst_ends[:k]

    @property
    def soundscape(self) -> Soundscape:
        """The :class:`stickslip.sim.sound.Soundscape` the virtual microphone renders with."""
        if self._soundscape is None:
            self._soundscape = _soundscape(self.sample_rate, self.seed, self.soundscape_kwargs)
        return self._soundscape

    def step_events(
        self, t_from: float, t_to: float
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]]:
        """Step events with ``t_from <= t < t_to``: ``(times_s, joints, at_stop)`` arrays."""
        times, joints, stops = [], [], []
        with self._lock:
            first = bisect.bisect_right(self._burst_ends, t_from)
            bursts = self._bursts[first:]
        for b in bursts:
            if b.t0 >= t_to:
                break
            if b.t_end <= t_from:
                continue
            k0 = max(0, math.ceil((t_from - b.t0) * b.hz - 1e-9))
            k1 = min(b.n, math.ceil((t_to - b.t0) * b.hz - 1e-9))
            if k1 <= k0:
                continue
            k = np.arange(k0, k1)
            times.append(b.t0 + k / b.hz)
            joints.append(np.full(k.size, b.joint, dtype=np.int64))
            stops.append(k >= b.k_stop)
        if not times:
            return np.empty(0), np.empty(0, dtype=np.int64), np.empty(0, dtype=bool)
        return np.concatenate(times), np.concatenate(joints), np.concatenate(stops)

    def stop_runs(self, joint: int | None = None) -> list[tuple[float, float]]:
        """``(begin, end)`` times (s, virtual clock) of runs of steps against an end stop.

        A run begins with the first step that began at a stop and lasts while the
        joint keeps stepping into it without a pause.
        """
        with self._lock:
            joints = (joint,) if joint is not None else (1, 2, 3)
            runs = [(a, e) for j in joints for a, e in self._runs[joint_number(j)]]
        return sorted(runs)

    def stop_times(self, joint: int | None = None) -> list[float]:
        """Times (s, virtual clock) when ``joint`` began stepping against a stop (true stops)."""
        return [a for a, _ in self.stop_runs(joint)]

    def add_listener(self, mic: VirtualMicrophone) -> None:
        """Keep the step events ``mic`` has not heard yet (held weakly: a dropped microphone frees them)."""
        self._mics.add(mic)

    def microphone(self, block: int = 1024, silent: bool = False) -> VirtualMicrophone:
        """A virtual microphone starting now on the virtual clock (blocks of ``block`` samples)."""
        return VirtualMicrophone(self, block, silent=silent)
