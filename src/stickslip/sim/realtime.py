"""The simulated arm in real time: ``sim://?realtime=1`` takes device time.

The simulated arms (:mod:`.arm`, :mod:`.physics`) run on a virtual clock: a burst of
5000 steps ends as soon as it is simulated, so nothing live (a position that moves on a
page, a STOP in the middle of a move, a jog held down) can be tried on them.
:class:`RealtimeArm` wraps either arm so that :meth:`~RealtimeArm.step` takes the time a
controller takes: it sends the steps in small chunks as the wall clock reaches them, at
the joint's stepping frequency (``speed`` times faster if asked), and
:meth:`~RealtimeArm.stop` from another thread ends the burst at the next step. A burst
ended early raises :class:`~stickslip.devices.base.BurstStopped` with the exact number
of steps made, so the move journal keeps the position it reached.

Device time (``clock_s``, what the virtual microphone renders against) is the arm's
virtual clock: it advances with the steps made, at the wall clock's pace while a burst
runs, and not while the host is busy between bursts (as on the virtual clock, the
microphone hears the bursts of a traverse back to back: the time the host takes to
listen to one burst is not multiplied by ``speed`` into silence).

URL options (besides the arm's own): ``realtime=1`` (this wrapper), ``speed=K``
(device time runs ``K`` times faster than the wall clock, ``0 < K <= 1000``; default 1).
``sim://?realtime=1&speed=10`` lets a day of calibration traverses run in a tenth of
the time.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

from .. import kinematics as kin
from ..calibration.result import Parameter
from ..devices.base import BurstStopped, DeviceError, DeviceInfo, StepsUncertain, check_steps
from ..models import JointModel
from .arm import SimulatedMM3A

__all__ = ["RealtimeArm", "TICK_S", "MAX_SPEED", "check_speed"]

TICK_S = 0.005
"""Wall-clock time between two chunks of a burst, s (a stop ends a burst within about this)."""

MAX_SPEED = 1000.0
"""Largest ``speed`` (device seconds per wall-clock second)."""


def check_speed(speed: object) -> float:
    """``speed`` as a float in ``(0, MAX_SPEED]``; ``ValueError`` naming the range otherwise."""
    try:
        v = float(speed)  # type: ignore[arg-type]  # any object: what float() refuses is caught below
    except (TypeError, ValueError):
        raise ValueError(f"speed must be a number in (0, {MAX_SPEED:g}], got {speed!r}") from None
    if isinstance(speed, bool) or not (math.isfinite(v) and 0.0 < v <= MAX_SPEED):
        raise ValueError(f"speed must be a number in (0, {MAX_SPEED:g}], got {speed!r}")
    return v


class RealtimeArm:
    """A simulated arm whose bursts take their time on the wall clock (a :class:`~stickslip.devices.base.Controller`).

    Parameters
    ----------
    arm : SimulatedMM3A
        The arm that simulates the steps (closed-form or physics-based).
    speed : float
        Device seconds per wall-clock second (1: real time), in ``(0, 1000]``.
    tick_s : float
        Wall-clock time between chunks of a burst, s, in ``[0.001, 0.1]``.
    clock : callable
        Monotonic wall clock, s (``time.monotonic``).
    url : str, optional
        The URL it was opened with (for :attr:`info`; default the arm's).

    Attributes
    ----------
    last_step_s : float or None
        ``clock()`` when the last chunk of steps was sent to the arm (for measuring how
        soon a stop takes effect), ``None`` before the first.
    """

    def __init__(
        self,
        arm: SimulatedMM3A,
        speed: float = 1.0,
        tick_s: float = TICK_S,
        clock: Callable[[], float] = time.monotonic,
        url: str | None = None,
    ):
        if not 0.001 <= float(tick_s) <= 0.1:
            raise ValueError(f"tick_s must be in [0.001, 0.1] s, got {tick_s!r}")
        self.arm = arm
        self._url = url
        self.speed = check_speed(speed)
        self.tick_s = float(tick_s)
        self._clock = clock
        self._cond = threading.Condition()
        self._stops = 0  # stop() calls so far: a burst ends when this changes
        self._burst = threading.Lock()  # one burst at a time, as a controller takes one command at a time
        self.last_step_s: float | None = None

    # ------------------------------------------------------------ Controller protocol

    @property
    def info(self) -> DeviceInfo:
        """The arm's info, its model marked as running in real time (and how fast)."""
        inner = self.arm.info
        extra = {**inner.extra, "realtime": True, "speed": self.speed}
        return DeviceInfo(self._url or inner.url, f"{inner.model}, real time", inner.joints, extra, inner.identity)

    def set_frequency(self, joint: int, hz: float) -> None:
        """Set the stepping frequency of ``joint``, Hz (the arm's range)."""
        self.arm.set_frequency(joint, hz)

    def frequency(self, joint: int) -> float:
        """The stepping frequency of ``joint``, Hz."""
        return self.arm.frequency(joint)

    def step(self, joint: int, n: int) -> None:
        """Step ``joint`` by ``n`` signed steps at its frequency, taking ``|n| / (f speed)`` of wall-clock time.

        Returns once the steps are made. A :meth:`stop` from another thread ends the
        burst at its next chunk: :class:`~stickslip.devices.base.BurstStopped` says how
        many steps were made (signed). A fault of the arm part-way
        (:class:`~stickslip.devices.base.DeviceError`) is raised as
        :class:`~stickslip.devices.base.StepsUncertain` with the steps made before it.
        """
        n = check_steps(n)
        self.arm._joint(joint)  # an unknown joint is refused before anything moves
        if n == 0:
            return
        sign = 1 if n > 0 else -1
        total = abs(n)
        with self._burst:
            with self._cond:
                stops = self._stops
            rate = self.arm.frequency(joint) * self.speed  # steps per wall-clock second
            t0 = self._clock()
            made = 0
            while made < total:
                due = min(total, int(math.floor((self._clock() - t0) * rate)) + 1)
                if due > made:
                    try:
                        self.arm.step(joint, sign * (due - made))
                    except DeviceError as e:
                        raise StepsUncertain(
                            f"{e} (after {sign * made:+d} of {n:+d} steps)", sign * made, sign * made
                        ) from None
                    made = due
                    self.last_step_s = self._clock()
                if made >= total:
                    break
                wait = min(self.tick_s, max(0.0, t0 + (total - 1) / rate - self._clock()))
                with self._cond:
                    if self._stops == stops:
                        self._cond.wait(wait)
                    if self._stops != stops:
                        raise BurstStopped(
                            f"stopped: joint {joint} made {sign * made:+d} of {n:+d} steps", sign * made
                        )

    def stop(self, joint: int | None = None) -> None:
        """End the burst in progress (on any joint) at its next chunk; nothing to do if none runs."""
        if joint is not None:
            self.arm._joint(joint)
        with self._cond:
            self._stops += 1
            self._cond.notify_all()

    def settings(self) -> dict[str, object]:
        """The arm's settings, and ``speed``."""
        return {**self.arm.settings(), "realtime": True, "speed": self.speed}

    def close(self) -> None:
        """Stop any burst and close the arm."""
        self.stop()
        self.arm.close()

    def __enter__(self) -> RealtimeArm:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ capabilities of the simulator

    @property
    def clock_s(self) -> float:
        """Device time, s (the arm's virtual clock: the steps made and the waits)."""
        return self.arm.clock_s

    @property
    def sample_rate(self) -> int:
        """Sample rate of the virtual microphone, Hz."""
        return self.arm.sample_rate

    def microphone(self, block: int = 1024, silent: bool = False) -> Any:
        """The arm's virtual microphone (:meth:`SimulatedMM3A.microphone`), starting now."""
        return self.arm.microphone(block, silent=silent)

    def set_pose(
        self,
        q1: float | None = None,
        q2: float | None = None,
        q3: float | None = None,
        theta: float | None = None,
        psi: float | None = None,
    ) -> None:
        """Place the joints and tilt the base (the experimenter's hands: no time passes)."""
        with self._burst:
            self.arm.set_pose(q1, q2, q3, theta, psi)

    @property
    def pose(self) -> kin.Pose:
        """The arm's true pose (joints rad, rad, m; tilt rad)."""
        return self.arm.pose

    def position(self, joint: int) -> float:
        """True position of ``joint`` (rad or m), as far as the burst in progress has gone."""
        return self.arm.position(joint)

    def at_stop(self, joint: int) -> str | None:
        """``"lower"`` or ``"upper"`` if ``joint`` rests on that end stop, else ``None``."""
        return self.arm.at_stop(joint)

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` of device time pass without stepping (``seconds / speed`` of wall-clock time)."""
        if not seconds >= 0.0:
            raise ValueError(f"wait time must be >= 0 s, got {seconds!r}")
        time.sleep(seconds / self.speed)
        self.arm.wait(seconds)

    def true_models(self) -> dict[tuple[int, str], JointModel]:
        """The day's true mean-step models (:meth:`SimulatedMM3A.true_models`)."""
        return self.arm.true_models()

    def true_parameters(self) -> list[Parameter]:
        """The day's true parameters (:meth:`SimulatedMM3A.true_parameters`)."""
        return self.arm.true_parameters()

    @property
    def steps_simulated(self) -> int:
        """Steps simulated so far."""
        return self.arm.steps_simulated
