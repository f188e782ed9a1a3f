"""A limit switch that cheats: it knows the simulated arm's true stop times (for tests and
emulators that need the traverse procedure without audio)."""

from __future__ import annotations

from typing import Any, Protocol

from numpy.typing import NDArray

from ..audio.events import StopEvent


class StoppingArm(Protocol):
    """What the oracle needs of the arm (``SimulatedMM3A`` is one)."""

    sample_rate: int

    def stop_runs(self, joint: int | None = None) -> list[tuple[float, float]]:
        """``(begin, end)`` times (s) of runs of steps against an end stop."""
        ...

__all__ = ["OracleStopDetector"]


class OracleStopDetector:
    """A limit switch that cheats: it knows the simulator's true stop times.

    For tests and emulators that need the traverse procedure without audio. It
    consumes blocks like the audio detectors (:class:`~stickslip.audio.events.StopDetector`; the stream
    time advances by the block length) and fires once per stop, at the end of the
    first block that reaches ``true stop + delay_s``; its onset estimate is the true
    stop plus ``onset_error_s``. A stop already sounding when the stream starts (or
    is reset) is heard from that moment, as a real detector would.

    Parameters
    ----------
    sim : SimulatedMM3A
    joint : int
        The joint whose stops it hears.
    delay_s : float
        Detection delay after the true stop, s.
    onset_error_s : float
        Error of the onset estimate, s.
    """

    uses_audio = False
    """It never looks at the samples, so the traverse's no-signal guard does not apply."""

    def __init__(
        self,
        sim: StoppingArm,
        joint: int,
        delay_s: float = 0.03,
        onset_error_s: float = 0.0,
        t0_s: float = 0.0,
    ):
        self.sim = sim
        self.joint = int(joint)
        self.delay_s = float(delay_s)
        self.onset_error_s = float(onset_error_s)
        self.sample_rate = sim.sample_rate
        self.reset(t0_s)

    @property
    def latency_s(self) -> float:
        """The detection delay, s."""
        return self.delay_s

    def reset(self, t0_s: float = 0.0, step_rate_hz: float | None = None) -> None:
        """Restart the stream at ``t0_s`` (s); stops before it are forgotten (the oracle ignores the step rate)."""
        self.t_s = float(t0_s)
        self._fired_upto = float(t0_s)

    def feed(self, block: NDArray[Any]) -> list[StopEvent]:
        """Consume a block; the events whose detection time falls within it."""
        t_end = self.t_s + len(block) / self.sample_rate
        self.t_s = t_end
        out = []
        for begin, end in self.sim.stop_runs(self.joint):
            # a run already under way when listening began is heard from then on
            onset = max(begin, self._fired_upto)
            if onset < end and onset + self.delay_s <= t_end:
                out.append(StopEvent(t_end, onset + self.onset_error_s, 0.0))
                self._fired_upto = max(end, t_end)
        return out
