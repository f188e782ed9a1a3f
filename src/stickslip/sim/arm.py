"""The simulated MM3A: the default backend (``sim://``), on a virtual clock.

A three-joint stick-slip arm with the paper's ranges (docs/design.md §2) whose
*true* mean step follows the load-aware models of :mod:`stickslip.models`, with
parameters that drift a few % from day to day (seeded by ``(seed, day)``), and
whose physics is deliberately **not** exactly Eqs. 3/8, so calibrations are tested
honestly:

* every step is drawn around the mean with multiplicative lognormal noise of
  relative standard deviation ``step_noise`` (mean exactly 1);
* the mean step carries a small smooth ripple along the joint's travel,
  ``1 + RIPPLE * sin(2 pi m (q - lower) / span + phase)`` (< 1 %, an integer number
  ``m`` of periods over the full range);
* the step is evaluated at the moving joint's *current* position at every step (the
  paper's step-by-step simulation, its Fig. 8), not averaged.

The *true parameters* (:meth:`SimulatedMM3A.true_parameters`) are those of Eq. 3/8
that reproduce the simulator's mean behaviour over full-range traverses: the ripple
has whole periods over the range, so it averages out to second order
(``RIPPLE**2 / 2`` ~ 1e-5 relative) and the lognormal noise has mean 1.

Hard end stops: a step that would cross a stop ends at the stop; steps that begin
at the stop do not move the joint and are recorded as *at-stop* steps, which the
virtual microphone (:class:`VirtualMicrophone`) renders with the joint's end-stop
sound through :class:`stickslip.sim.sound.Soundscape`.

The virtual clock ``clock_s`` advances by ``|n| / frequency`` per burst; a burst is
simulated at once with numpy (chunked fixed-point iteration of the step positions),
so a 90 s rotary traverse takes a few milliseconds.
"""

from __future__ import annotations

import math
import numbers
import threading
import weakref
import zlib
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qsl, urlsplit

import numpy as np
from numpy.typing import NDArray

from .. import kinematics as kin
from ..devices.base import DeviceError, DeviceInfo, check_setting, check_steps
from ..joints import tilt_problem
from ..models import JointModel, PrismaticParams, RotaryParams, direction_sign
from .step_log import StepLog
from .true_steps import _CHUNK as _CHUNK  # sim.physics steps in the same chunks
from .true_steps import RIPPLE, TrueSteps

if TYPE_CHECKING:
    pass

__all__ = [
    "NOMINAL",
    "FREQUENCY_RANGE",
    "RIPPLE",
    "SimulatedMM3A",
    "open_url",
    "day_key",
]

FREQUENCY_RANGE = (1.0, 5000.0)
"""Allowed stepping frequencies of the simulated controller, Hz."""

_MAX_BURST = 10_000_000

# Nominal (undrifted) true parameters. Prismatic: the paper's published values
# (docs/design.md §3, units nm). Joint 2: d from the paper's Fig. 10 (q3 = 0:
# d- = 3.83, d+ = -8.15 urad; q3 = 12 mm: d- = 23.94, d+ = -19.40 urad); gamma0 in the
# 40-60 urad the paper's rotary steps show. Joint 1 is not calibrated in the paper:
# values of the same size.
NOMINAL: dict[tuple[int, str], PrismaticParams | RotaryParams] = {
    (3, "+"): PrismaticParams(972e-9, 0.27, 372e-9),
    (3, "-"): PrismaticParams(899e-9, 0.25, -436e-9),
    (2, "+"): RotaryParams((52.0e-6, 47.0e-6), (-8.15e-6, -19.40e-6)),
    (2, "-"): RotaryParams((49.0e-6, 45.0e-6), (3.83e-6, 23.94e-6)),
    (1, "+"): RotaryParams((50.0e-6, 46.0e-6), (-7.0e-6, -15.0e-6)),
    (1, "-"): RotaryParams((48.0e-6, 44.0e-6), (5.0e-6, 17.0e-6)),
}


def day_key(day: str | int) -> int:
    """A stable integer for a day label (an int is used as is; a string is hashed with CRC-32)."""
    if isinstance(day, (int, np.integer)):
        return int(day) & 0xFFFFFFFF
    return zlib.crc32(str(day).strip().encode("utf-8"))


def _drifted(
    params: PrismaticParams | RotaryParams, rng: np.random.Generator, drift: float
) -> PrismaticParams | RotaryParams:
    """``params`` with every value multiplied by ``1 + drift * z``, z ~ N(0, 1) clipped to +-2.5."""

    def f() -> float:
        return 1.0 + drift * float(np.clip(rng.standard_normal(), -2.5, 2.5))

    if isinstance(params, PrismaticParams):
        return PrismaticParams(params.a * f(), params.b * f(), params.c * f())
    return RotaryParams(
        (params.gamma0[0] * f(), params.gamma0[1] * f()),
        (params.d[0] * f(), params.d[1] * f()),
        params.knots,
    )


class SimulatedMM3A(TrueSteps, StepLog):
    """A simulated Kleindiek MM3A on a virtual clock (a :class:`~.base.Controller`).

    Parameters
    ----------
    seed : int
        Seeds the day-to-day drift of the true parameters, the per-step noise and the
        room sound.
    day : str or int
        Session label (ISO date preferred); the true parameters drift with ``(seed, day)``.
    step_noise : float
        Relative standard deviation of a single step around its mean (lognormal,
        mean 1), dimensionless, in [0, 0.5]. Default 0.03.
    drift : float
        Relative standard deviation of the day-to-day drift of every true parameter
        from :data:`NOMINAL`, dimensionless, in [0, 0.2]. Default 0.03.
    sample_rate : int
        Sample rate of the virtual microphone, Hz.
    soundscape_kwargs : dict, optional
        Passed to :class:`stickslip.sim.sound.Soundscape` (gain_db, noise_db, hum,
        knocks_per_min, babble, ...).
    pose : Pose, optional
        Initial pose (joints rad, rad, m; tilt rad). Default: the outstretched pose
        ``q1 = 0, q2 = -pi/2, q3 = 0``, level base.
    url : str
        The URL it was opened with (for :attr:`info`).

    Examples
    --------
    >>> sim = SimulatedMM3A(seed=1, day="2026-11-22")
    >>> sim.step(3, 1000)            # 1000 steps out, 1 s on the virtual clock
    >>> round(sim.clock_s, 3)
    1.0
    """

    def __init__(
        self,
        seed: int = 0,
        day: str | int = 0,
        step_noise: float = 0.03,
        drift: float = 0.03,
        sample_rate: int = 48_000,
        soundscape_kwargs: dict[str, Any] | None = None,
        pose: kin.Pose | None = None,
        url: str = "sim://",
    ):
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**63:
            raise ValueError(f"seed = {seed!r} must be an integer in [0, 2**63)")
        if not 0.0 <= float(step_noise) <= 0.5:
            raise ValueError(f"step_noise = {step_noise!r} is outside [0, 0.5] (relative standard deviation)")
        if not 0.0 <= float(drift) <= 0.2:
            raise ValueError(f"drift = {drift!r} is outside [0, 0.2] (relative standard deviation)")
        if not 8000 <= int(sample_rate) <= 384_000:
            raise ValueError(f"sample_rate = {sample_rate!r} Hz is outside [8000, 384000] Hz")
        self.seed = int(seed)
        self.day = day
        self.day_label = str(day)
        self.step_noise = float(step_noise)
        self.drift = float(drift)
        self.sample_rate = int(sample_rate)
        self.soundscape_kwargs = dict(soundscape_kwargs or {})
        self._url = url
        key = day_key(day)
        drift_rng = np.random.default_rng([self.seed, key, 0])
        self._models = {}
        for (joint, direction), nominal in NOMINAL.items():
            self._models[(joint, direction)] = JointModel(joint, direction, _drifted(nominal, drift_rng, self.drift))
        self._ripple_phase = {j: float(drift_rng.uniform(0.0, 2.0 * math.pi)) for j in (1, 2, 3)}
        self._rng = np.random.default_rng([self.seed, key, 1])
        self._sigma = math.sqrt(math.log1p(self.step_noise**2))
        p = pose if pose is not None else kin.Pose()
        self._q = {1: 0.0, 2: 0.0, 3: 0.0}
        self._theta = 0.0
        self._psi = 0.0
        self.set_pose(*p)
        self._hz = {1: 1000.0, 2: 1000.0, 3: 1000.0}
        self.clock_s = 0.0
        self._bursts = []
        self._burst_ends = []
        self._runs = {1: [], 2: [], 3: []}
        self._last_burst = {1: None, 2: None, 3: None}
        self._mics = weakref.WeakSet()
        self._lock = threading.RLock()  # emulators step from a server thread
        self._soundscape = None
        self.steps_simulated = 0
        self._closed = False

    # ------------------------------------------------------------ Controller protocol

    @property
    def info(self) -> DeviceInfo:
        """Model, URL, joints and the simulation settings (seed, day, noise, drift)."""
        return DeviceInfo(
            self._url,
            "simulated MM3A",
            (1, 2, 3),
            {
                "seed": self.seed,
                "day": self.day_label,
                "step_noise": self.step_noise,
                "drift": self.drift,
                "sample_rate_hz": self.sample_rate,
            },
            identity=f"simulator seed {self.seed}",
        )

    def set_frequency(self, joint: int, hz: float) -> None:
        """Set the stepping frequency of ``joint``, Hz, in [1, 5000]; else ``ValueError``."""
        joint = self._joint(joint)
        self._hz[joint] = check_setting("frequency", hz, *FREQUENCY_RANGE, unit="Hz")

    def frequency(self, joint: int) -> float:
        """The stepping frequency of ``joint``, Hz (default 1000 Hz)."""
        return self._hz[self._joint(joint)]

    def step(self, joint: int, n: int) -> None:
        """Step ``joint`` by ``n`` signed steps; the virtual clock advances by ``|n| / f``.

        Stepping into an end stop does not move the joint past it; those steps are
        recorded as at-stop steps (heard by the virtual microphone).
        """
        self._check_open()
        joint = self._joint(joint)
        n = check_steps(n)
        if n == 0:
            return
        if abs(n) > _MAX_BURST:
            raise DeviceError(f"a burst of {abs(n)} steps is more than the controller accepts ({_MAX_BURST})")
        sign = 1 if n > 0 else -1
        with self._lock:
            hz = self._hz[joint]
            k_stop, q_end = self._advance(joint, sign, abs(n))
            self._q[joint] = q_end
            self._log_burst(self.clock_s, hz, joint, abs(n), k_stop, sign)
            self.clock_s += abs(n) / hz
            self.steps_simulated += abs(n)

    def stop(self, joint: int | None = None) -> None:
        """Stop ``joint`` (or all). Bursts complete at once on the virtual clock: a no-op."""
        if joint is not None:
            self._joint(joint)

    def settings(self) -> dict[str, object]:
        """Frequencies (Hz) per joint and the simulation settings."""
        return {
            "frequency_hz": dict(self._hz),
            "seed": self.seed,
            "day": self.day_label,
            "step_noise": self.step_noise,
            "drift": self.drift,
            "sample_rate_hz": self.sample_rate,
        }

    def close(self) -> None:
        """Stop everything; further steps raise :class:`DeviceError`."""
        self._closed = True

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceError("the simulated MM3A is closed")

    def __enter__(self) -> SimulatedMM3A:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ the experimenter's hands

    def set_pose(
        self,
        q1: float | None = None,
        q2: float | None = None,
        q3: float | None = None,
        theta: float | None = None,
        psi: float | None = None,
    ) -> None:
        """Place joints and tilt the base (teleport; no steps, no sound). ``None`` keeps a value.

        Joints rad, rad, m within their stops; ``theta`` and ``psi`` rad within [-pi, pi].
        Raises ``ValueError`` naming the allowed range.
        """
        for j, v in ((1, q1), (2, q2), (3, q3)):
            if v is None:
                continue
            spec = kin.JOINTS[j]
            v = _number(f"q{j}", v, spec.unit)
            problem = spec.range_problem(f"q{j}", v)
            if problem:
                raise ValueError(problem)
            self._q[j] = min(max(v, spec.lower), spec.upper)  # within the contains() tolerance
        for name, v in (("theta", theta), ("psi", psi)):
            if v is None:
                continue
            v = _number(name, v, "rad")
            if (problem := tilt_problem(name, v)) is not None:
                raise ValueError(problem)
            setattr(self, f"_{name}", v)

    def position(self, joint: int) -> float:
        """True position of ``joint`` (rad or m)."""
        return self._q[self._joint(joint)]

    def at_stop(self, joint: int) -> str | None:
        """``"lower"`` or ``"upper"`` if ``joint`` rests on that end stop, else ``None``."""
        spec = kin.JOINTS[self._joint(joint)]
        q = self._q[joint]
        if q <= spec.lower:
            return "lower"
        if q >= spec.upper:
            return "upper"
        return None

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` pass on the virtual clock without stepping (the room is heard)."""
        if not seconds >= 0.0:
            raise ValueError(f"wait time must be >= 0 s, got {seconds!r}")
        self.clock_s += float(seconds)

    def labelled_recording(
        self, joint: int, direction: str | int = "+", before_s: float = 2.0, after_s: float = 1.0
    ) -> tuple[NDArray[np.float32], int, float]:
        """Record stepping into an end stop, for tuning the limit switch.

        Places ``joint`` so that stepping in ``direction`` reaches its stop after about
        ``before_s`` seconds, steps for ``before_s + after_s`` seconds and returns
        ``(samples, sample_rate, stop_at_s)`` with the true time of the first at-stop
        step, s from the start of the recording.
        """
        joint = self._joint(joint)
        sign = direction_sign(direction)
        spec = kin.JOINTS[joint]
        hz = self._hz[joint]
        stop = spec.upper if sign > 0 else spec.lower
        n_before = int(round(before_s * hz))
        mean = float(self.true_mean_step(joint, sign, stop))
        start = stop - sign * min(n_before * mean, 0.9 * spec.span)
        self.set_pose(**{f"q{joint}": start})
        mic = self.microphone()
        t0 = self.clock_s
        n_total = int(round((before_s + after_s) * hz))
        self.step(joint, sign * n_total)
        stops = [t for t in self.stop_times(joint) if t >= t0]
        if not stops:
            raise DeviceError("the recording never reached the stop (internal error)")
        samples = mic.read_until(self.clock_s)
        return samples, self.sample_rate, stops[0] - t0


# ---------------------------------------------------------------- URL


_URL_KEYS = {
    "seed": int,
    "day": str,
    "noise": float,
    "drift": float,
    "rate": int,
    "gain_db": float,
}


def _number(name: str, v: object, unit: str) -> float:
    """``v`` as a float, or a TypeError naming it (q2="a" was "could not convert string to float: 'a'")."""
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name} = {v!r} must be a number in {unit}")
    return float(v)


def open_url(url: str = "sim://") -> SimulatedMM3A:
    """Open the closed-form simulated MM3A from a ``sim://`` URL.

    ``sim://`` URLs reach this through :func:`stickslip.sim.urls.open_url`, which sends
    ``?physics=1`` to the physics-based arm instead.

    Query options: ``seed`` (int), ``day`` (label), ``noise`` (relative per-step
    noise, e.g. 0.03), ``drift`` (relative day-to-day drift), ``rate`` (microphone
    sample rate, Hz), ``gain_db`` (microphone gain, dB). Example:
    ``sim://?seed=3&day=2026-11-22&noise=0.03``. Unknown keys or bad values raise
    ``ValueError`` naming them.
    """
    parts = urlsplit(url)
    if parts.scheme not in ("sim", ""):
        raise ValueError(f"not a sim:// URL: {url!r}")
    if parts.path not in ("", "/") or parts.netloc not in ("", "mm3a", "localhost"):
        raise ValueError(f"a sim:// URL takes only query options (e.g. sim://?seed=3), got {url!r}")
    opts: dict[str, Any] = {}
    for key, value in parse_qsl(parts.query, keep_blank_values=True, strict_parsing=False):
        if key not in _URL_KEYS:
            known = ", ".join(sorted(_URL_KEYS))
            raise ValueError(f"unknown sim:// option {key!r} in {url!r} (known: {known})")
        try:
            opts[key] = _URL_KEYS[key](value)
        except ValueError:
            raise ValueError(f"sim:// option {key}={value!r} is not a valid {_URL_KEYS[key].__name__}") from None
    scape = {"gain_db": opts["gain_db"]} if "gain_db" in opts else None
    return SimulatedMM3A(
        seed=int(opts.get("seed", 0)),
        day=opts.get("day", 0),
        step_noise=float(opts.get("noise", 0.03)),
        drift=float(opts.get("drift", 0.03)),
        sample_rate=int(opts.get("rate", 48_000)),
        soundscape_kwargs=scape,
        url=url,
    )

