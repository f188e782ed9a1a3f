"""Teleoperation: keys become tip velocities, velocities become step rates (resolved-rate control).

The control law, in the spirit of the resolved-rate teleoperation the paper points to
(its reference [17]) and docs/design.md §9:

1. a key gives a tip velocity ``v`` (m/s) along ±x, ±y or ±z of the base frame, or of
   an *image frame* turned by ``image_angle`` about z0 (to match the microscope);
2. the joint velocities are ``dq = J⁻¹ v`` (:func:`stickslip.kinematics.joint_rates`);
3. each joint's step rate is ``dq_j / gamma_j`` (steps/s), ``gamma_j`` the calibrated
   mean step of that joint in that direction in the current pose (the models include
   gravity, so the rates change as the arm moves);
4. if any rate exceeds its joint's maximum step rate, *all* rates are scaled down by
   the same factor (the tip slows down but keeps its direction);
5. every tick the rates times the tick's duration are added to each joint's step
   accumulator; whole steps are sent and the fraction is carried to the next tick.

:class:`JogController` is that law as a pure object (keys and a clock in, signed step
counts out; no I/O); :func:`run_jog` is the loop that reads keys, steps a device
through the move journal (:func:`stickslip.procedures.move.drive`) and shows the
status; :func:`jog` is the whole session behind ``stickslip jog`` (the lock, the kept
state, the device). The terminal (raw keys, the status lines) lives in the CLI and comes
in as a :class:`KeySource` and a ``show`` function.

Keys (names as :func:`parse_keys` returns them):

=================  ==========================================================
``left``/``right`` ∓x   (also ``a``/``d``)
``up``/``down``    ±y   (also ``w``/``s``)
``pgup``/``pgdn``  ±z   (also ``r``/``f``)
``space``          stop at once
``1`` … ``7``      speed 0.1, 0.3, 1, 3, 10, 30, 100 µm/s (``+``/``-``: next/previous)
``m``              single-step mode on/off: each direction key moves the tip by the
                   speed preset's distance (0.1–100 µm), planned like ``reach``
``b``              base frame / image frame
``[``/``]``        turn the image frame by -15°/+15°
``q``              quit
=================  ==========================================================

In continuous mode a direction key moves the tip until ``space``, another direction,
or until no key has come for ``hold`` seconds (a held key repeats; releasing it stops
the tip): a dead man's switch.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Protocol

import numpy as np

from .. import kinematics as kin
from ..calibration import Calibration
from ..devices.base import Controller, DeviceError, PoseSettable, device_key, open_device
from ..devices.identity import open_checked
from ..devices.positions import DeviceState, save_state
from ..motion.reach import JointStepper, plan_reach
from ..rig.envelope import EnvelopeViolation, SigmaGrowth
from ..rig.guard import Guard
from .conditions import calibration_device_problem, usage_warnings
from .move import (
    MoveRefused,
    MoveStore,
    PoseUpdate,
    device_lock,
    drive,
    exact_positions,
    grow_track,
    mark_claim,
    release_claim,
    sharing_controller,
    sigma_growth,
    simulates,
    tracked_calibration,
)
from .reach import referenced_state

if TYPE_CHECKING:
    from .closed_loop import CameraLoop, JogEyes

__all__ = [
    "SPEEDS",
    "DIRECTION_KEYS",
    "JogStatus",
    "JogController",
    "JogRequest",
    "JogResult",
    "KeySource",
    "envelope_stop",
    "jog",
    "max_rates",
    "parse_keys",
    "run_jog",
]

SPEEDS = (0.1e-6, 0.3e-6, 1e-6, 3e-6, 10e-6, 30e-6, 100e-6)
"""Speed presets, m/s (keys 1 to 7); in single-step mode, the distance per key press, m."""

DIRECTION_KEYS: dict[str, tuple[float, float, float]] = {
    "left": (-1.0, 0.0, 0.0),
    "right": (1.0, 0.0, 0.0),
    "up": (0.0, 1.0, 0.0),
    "down": (0.0, -1.0, 0.0),
    "pgup": (0.0, 0.0, 1.0),
    "pgdn": (0.0, 0.0, -1.0),
    "a": (-1.0, 0.0, 0.0),
    "d": (1.0, 0.0, 0.0),
    "w": (0.0, 1.0, 0.0),
    "s": (0.0, -1.0, 0.0),
    "r": (0.0, 0.0, 1.0),
    "f": (0.0, 0.0, -1.0),
}
"""Unit tip directions in the active frame (base or image)."""

_ESCAPES = {
    b"\x1b[A": "up",
    b"\x1b[B": "down",
    b"\x1b[C": "right",
    b"\x1b[D": "left",
    b"\x1bOA": "up",
    b"\x1bOB": "down",
    b"\x1bOC": "right",
    b"\x1bOD": "left",
    b"\x1b[5~": "pgup",
    b"\x1b[6~": "pgdn",
}
_WINDOWS = {b"H": "up", b"P": "down", b"M": "right", b"K": "left", b"I": "pgup", b"Q": "pgdn"}


def _skip_escape(data: bytes, i: int) -> int:
    """Index after the escape sequence at ``i``: CSI (``ESC [`` ... final byte), SS3 (``ESC O x``), or a lone ESC."""
    if data[i + 1 : i + 2] == b"[":
        j = i + 2
        while j < len(data) and not 0x40 <= data[j] <= 0x7E:
            j += 1
        return j + 1
    if data[i + 1 : i + 2] == b"O":
        return i + 3
    return i + 1


def parse_keys(data: bytes) -> list[str]:
    """Key names from raw terminal bytes: ANSI arrows and PgUp/PgDn, Windows ``\\xe0`` codes, letters.

    Letters are lower-cased; a space is ``"space"``, Ctrl-C ``"q"``; anything else unknown
    is dropped.
    """
    keys: list[str] = []
    i = 0
    while i < len(data):
        if data[i] == 0x1B:
            for seq, name in _ESCAPES.items():
                if data.startswith(seq, i):
                    keys.append(name)
                    i += len(seq)
                    break
            else:
                i = _skip_escape(data, i)  # a lone escape or an unknown sequence: skip it whole
            continue
        if data[i] in (0x00, 0xE0) and i + 1 < len(data):  # msvcrt's two-byte keys
            special = _WINDOWS.get(data[i + 1 : i + 2])
            if special:
                keys.append(special)
            i += 2
            continue
        c = chr(data[i]).lower()
        i += 1
        if c == " ":
            keys.append("space")
        elif c == "\x03":
            keys.append("q")
        elif c in "1234567+-=mbq[]" or c in DIRECTION_KEYS:
            keys.append("+" if c == "=" else c)
    return keys


@dataclass
class JogStatus:
    """What the status display shows (SI units).

    Attributes
    ----------
    q : tuple of float
        Predicted joints (rad, rad, m).
    tip : tuple of float
        Predicted tip, base frame, m.
    to_limits : tuple of float
        Each joint's distance to its nearer end stop (rad, rad, m).
    speed : float
        Speed preset, m/s (single-step mode: distance per press, m).
    velocity : tuple of float
        Commanded tip velocity, base frame, m/s (after the rate cap).
    rates : tuple of float
        Step rates of joints 1, 2, 3, steps/s (signed).
    single_step : bool
    image_frame : bool
    image_angle : float
        rad.
    sent : list of int
        Signed steps sent per joint since the start.
    message : str
        The last notice (a limit, a singular pose, a device error).
    """

    q: tuple[float, float, float]
    tip: tuple[float, float, float]
    to_limits: tuple[float, float, float]
    speed: float
    velocity: tuple[float, float, float]
    rates: tuple[float, float, float]
    single_step: bool
    image_frame: bool
    image_angle: float
    sent: list[int]
    message: str
    sources: tuple[str, str, str] = ("", "", "")
    """Each joint's kept source when a camera looks (``seen``, ``dead-reckoned``), else empty."""
    kinds: tuple[str, str, str] = ("rotary", "rotary", "prismatic")
    """Each joint's kind (the arm's: an ``xyz`` stage's are all prismatic), for the units it is shown in."""


@dataclass
class JogController:
    """The resolved-rate law as a pure object: keys and time in, signed step counts out.

    Parameters
    ----------
    calibration : Calibration
        Step-size models of joints 1, 2, 3.
    q : sequence of 3 floats
        Predicted joints at the start (rad, rad, m); updated by dead reckoning.
    theta, psi : float
        Base tilt, rad.
    geometry : Geometry
    max_rate : tuple of 3 floats
        Each joint's maximum step rate, steps/s (the controller's stepping frequency).
    image_angle : float
        Rotation of the image frame about z0, rad.
    hold : float
        Seconds a direction key keeps the tip moving without a repeat (0: until ``space``).
    speed_index : int
        Index into :data:`SPEEDS` (default 3: 3 µm/s).
    margin : float
        Motion stops when a joint would come closer than this fraction of its range to
        an end stop (dimensionless).
    guard : Guard or None
        A rig's envelope: motion stops before a tick whose steps would leave it (so within
        one tick's motion of the boundary), with ``guard_sd`` (rad, rad, m) as the joints' σ, or
        the σ model (:func:`~.move.sigma_growth`) that grows with every tick let through.
    joints : JointSet or None
        The arm's joints (a rig file's arm); the MM3A's by default.
    stage : Stage or None
        A Cartesian arm's kinematics (a rig file's ``xyz`` arm): ``dq = A^-T v`` in every
        pose, and ``geometry`` is not used.
    """

    calibration: Calibration
    q: list[float]
    theta: float = 0.0
    psi: float = 0.0
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY
    max_rate: tuple[float, float, float] = (1000.0, 1000.0, 1000.0)
    image_angle: float = 0.0
    hold: float = 0.5
    speed_index: int = 3
    margin: float = 1e-3
    image_frame: bool = False
    single_step: bool = False
    direction: tuple[float, float, float] | None = None
    quit: bool = False
    message: str = ""
    sent: list[int] = field(default_factory=lambda: [0, 0, 0])
    sources: tuple[str, str, str] = ("", "", "")
    _acc: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    _last_key_t: float = 0.0
    _rates: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _pending: list[tuple[int, int, int]] = field(default_factory=list)
    _setpoint: tuple[float, float, float] | None = None
    _queued: list[tuple[float, float, float]] = field(default_factory=list)
    guard: Guard | None = None
    guard_sd: tuple[float, float, float] | SigmaGrowth = (0.0, 0.0, 0.0)
    joints: kin.JointSet | None = None
    stage: kin.Stage | None = None
    mark: Callable[[list[list[float]]], None] | None = None
    """Claims a tick's path (poses) in the store before the other arms are read again (:func:`~.move.mark_claim`)."""
    unmark: Callable[[], None] | None = None
    """Takes the tick's claim back once the jog stands still (:func:`~.move.release_claim`)."""
    _marked: bool = False

    def _spec(self, joint: int) -> kin.JointSpec:
        return kin.joint_spec(joint, self.joints)

    def _tip(self, q: tuple[float, float, float]) -> np.ndarray:
        return self.stage.tip(q) if self.stage is not None else kin.tip(q, self.geometry)

    def __post_init__(self) -> None:
        self.q = [float(v) for v in self.q]
        if not all(r > 0 and math.isfinite(r) for r in self.max_rate):
            raise ValueError(f"max_rate = {self.max_rate} must be positive step rates (steps/s)")
        if not 0 <= self.speed_index < len(SPEEDS):
            raise ValueError(f"speed_index = {self.speed_index} must be in [0, {len(SPEEDS) - 1}]")

    # ---------------------------------------------------------------- keys

    @property
    def speed(self) -> float:
        """The speed preset, m/s (single-step mode: the distance per key press, m)."""
        return SPEEDS[self.speed_index]

    def frame(self) -> np.ndarray:
        """Columns: the active frame's x, y, z axes in the base frame."""
        a = self.image_angle if self.image_frame else 0.0
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def press(self, key: str, t: float) -> None:
        """Handle one key at time ``t`` (s, any monotonic clock)."""
        if key == "q":
            self.quit = True
            self.stop()
        elif key == "space":
            self.stop()
            self.message = "stopped"
        elif key in "1234567" and len(key) == 1:
            self.speed_index = int(key) - 1
        elif key == "+":
            self.speed_index = min(self.speed_index + 1, len(SPEEDS) - 1)
        elif key == "-":
            self.speed_index = max(self.speed_index - 1, 0)
        elif key == "m":
            self.stop()
            self.single_step = not self.single_step
        elif key == "b":
            self.stop()
            self.image_frame = not self.image_frame
        elif key in ("[", "]"):
            self.stop()
            self.image_angle += math.radians(15.0 if key == "]" else -15.0)
            self.image_angle = math.remainder(self.image_angle, 2 * math.pi)
        elif key in DIRECTION_KEYS:
            d = self.frame() @ np.array(DIRECTION_KEYS[key])
            direction = (float(d[0]), float(d[1]), float(d[2]))
            if self.single_step:
                self._single_step(direction)
            else:
                if direction != self.direction:
                    self._acc = [0.0, 0.0, 0.0]
                self.direction = direction
                self._last_key_t = t
                self.message = ""

    def stop(self) -> None:
        """Stop at once: no velocity, no pending steps, accumulators cleared."""
        self.direction = None
        self._pending.clear()
        self._queued.clear()
        self._acc = [0.0, 0.0, 0.0]
        self._rates = (0.0, 0.0, 0.0)
        self._velocity = (0.0, 0.0, 0.0)
        self._setpoint = None

    # ---------------------------------------------------------------- the law

    def gamma(self, joint: int, sign: int) -> float:
        """Calibrated mean step of ``joint`` in direction ``sign`` at the predicted pose (rad or m)."""
        pose = kin.Pose(self.q[0], self.q[1], self.q[2], self.theta, self.psi)
        stepper = JointStepper(self.calibration, self._spec(joint), pose)
        return float(abs(stepper.position_after(self.q[joint - 1], sign) - self.q[joint - 1]))

    def rates(self, v: tuple[float, float, float]) -> tuple[tuple[float, float, float], float]:
        """Step rates (steps/s, signed) for tip velocity ``v`` (m/s), and the cap's scale factor (<= 1).

        ``dq = J⁻¹ v``; ``rate_j = dq_j / gamma_j``; all scaled by one factor so that
        none exceeds its joint's maximum. Raises ``SingularPose`` near joint 1's axis.
        """
        dq = self.stage.joint_rates(v) if self.stage is not None else kin.joint_rates(self.q, v, self.geometry)
        raw = []
        for j in (1, 2, 3):
            if dq[j - 1] == 0.0:
                raw.append(0.0)
                continue
            sign = 1 if dq[j - 1] > 0 else -1
            raw.append(float(dq[j - 1]) / self.gamma(j, sign))
        scale = min([1.0] + [self.max_rate[j] / abs(r) for j, r in enumerate(raw) if r])
        return (raw[0] * scale, raw[1] * scale, raw[2] * scale), scale

    def tick(self, t: float, dt: float) -> tuple[int, int, int]:
        """Advance by ``dt`` seconds at time ``t``; the signed steps to send now (joint 1, 2, 3).

        The caller sends them in that order and then calls :meth:`sent_steps` with what
        the device confirmed (which updates the predicted joints). In a rig, a tick's range
        is claimed before the other arms are read (``mark``), and the claim taken back once
        the jog stands still (``unmark``).
        """
        out = self._tick(t, dt)
        if self._marked and self.direction is None and not self._pending and not any(out):
            self._marked = False
            if self.unmark is not None:
                self.unmark()
        return out

    def _tick(self, t: float, dt: float) -> tuple[int, int, int]:
        if not self._pending and self._queued:
            self._single_step(self._queued.pop(0))
        if self._pending:  # a single step's segments: checked as a held key's ticks are
            return self._checked(self._pending.pop(0))
        if self.direction is None:
            return (0, 0, 0)
        if self.hold > 0 and t - self._last_key_t > self.hold:
            self.stop()
            return (0, 0, 0)
        v_req = tuple(self.speed * c for c in self.direction)
        try:
            rates, scale = self.rates((v_req[0], v_req[1], v_req[2]))
        except (kin.SingularPose, ValueError) as e:
            self.stop()
            self.message = str(e)
            return (0, 0, 0)
        self._rates = rates
        self._velocity = (v_req[0] * scale, v_req[1] * scale, v_req[2] * scale)
        steps = []
        for j in (1, 2, 3):
            self._acc[j - 1] += rates[j - 1] * dt
            n = int(self._acc[j - 1])  # whole steps now, the fraction carried
            self._acc[j - 1] -= n
            steps.append(n)
        return self._checked((steps[0], steps[1], steps[2]))

    def _checked(self, out: tuple[int, int, int]) -> tuple[int, int, int]:
        """``out``, or no steps and a stop with the message if they would pass a joint's limit or leave the rig's
        envelope (:meth:`_limit_problem`)."""
        problem = self._limit_problem(out)
        if problem:
            self.stop()
            self.message = problem
            return (0, 0, 0)
        return out

    def _limit_problem(self, steps: tuple[int, int, int]) -> str | None:
        q = list(self.q)
        path = [list(q)]
        for j in (1, 2, 3):
            if steps[j - 1]:
                pose = kin.Pose(q[0], q[1], q[2], self.theta, self.psi)
                before = q[j - 1]
                spec = self._spec(j)
                q[j - 1] = JointStepper(self.calibration, spec, pose).position_after(before, steps[j - 1])
                guard = self.margin * spec.span
                # inside the guard band and going further in (moving away from a stop is always allowed)
                if (q[j - 1] < spec.lower + guard and q[j - 1] < before) or (
                    q[j - 1] > spec.upper - guard and q[j - 1] > before
                ):
                    side = "lower" if q[j - 1] < before else "upper"
                    return f"joint {j} is at its {side} limit: stopped (move the other way)"
                path.append(list(q))
        rig_guard = self.guard
        if rig_guard is not None and rig_guard.fresh is not None and len(path) > 1:
            if self.mark is not None:  # "mark, then check": the tick's range claimed before the others are read
                self.mark(path)
                self._marked = True
            rig_guard = rig_guard.fresh()  # the other arms as kept now: one that started to move stops this jog
        problem = envelope_stop(rig_guard, path, self.guard_sd)
        if problem is None and isinstance(self.guard_sd, SigmaGrowth) and len(path) > 1:
            self.guard_sd = self.guard_sd.after(path)  # the σ the tick's steps leave, for the next tick
        return problem

    def _single_step(self, direction: tuple[float, float, float]) -> None:
        """Plan a straight move of ``speed`` metres along ``direction``; queue its segments."""
        if self._pending:  # the previous press is still being sent: this one follows it
            if len(self._queued) < 10:
                self._queued.append(direction)
            return
        q_now = (self.q[0], self.q[1], self.q[2])
        start = self._setpoint if self._setpoint is not None else tuple(float(c) for c in self._tip(q_now))
        target = tuple(start[i] + self.speed * direction[i] for i in range(3))
        try:
            plan = plan_reach(
                self.calibration,
                kin.Pose(*q_now, self.theta, self.psi),
                to=target,
                geometry=self.geometry,
                segment=max(self.speed / 4, 1e-7),
                stage=self.stage,
                joints=self.joints,
            )
        except (kin.OutOfReach, kin.SingularPose, KeyError, ValueError) as e:
            self.message = str(e).strip("'\"")
            return
        self._setpoint = (target[0], target[1], target[2])  # the fraction of a step not taken is kept
        self._pending = [s.steps for s in plan.segments if any(s.steps)]
        self.message = ""

    def sent_steps(self, joint: int, n: int) -> None:
        """Record ``n`` signed steps of ``joint`` confirmed by the device (dead reckoning)."""
        if n == 0:
            return
        pose = kin.Pose(self.q[0], self.q[1], self.q[2], self.theta, self.psi)
        self.q[joint - 1] = JointStepper(self.calibration, self._spec(joint), pose).position_after(self.q[joint - 1], n)
        self.sent[joint - 1] += n

    def status(self) -> JogStatus:
        """The current :class:`JogStatus`."""
        q = (self.q[0], self.q[1], self.q[2])
        p = self._tip(q)
        specs = [self._spec(j) for j in (1, 2, 3)]
        lim = tuple(min(self.q[j - 1] - specs[j - 1].lower, specs[j - 1].upper - self.q[j - 1]) for j in (1, 2, 3))
        return JogStatus(
            q,
            (float(p[0]), float(p[1]), float(p[2])),
            (lim[0], lim[1], lim[2]),
            self.speed,
            self._velocity,
            self._rates,
            self.single_step,
            self.image_frame,
            self.image_angle,
            list(self.sent),
            self.message,
            self.sources,
            (specs[0].kind, specs[1].kind, specs[2].kind),
        )


def run_jog(
    dev: Controller,
    state: DeviceState,
    controller: JogController,
    read_keys: Callable[[float], list[str]],
    show: Callable[[JogStatus], None],
    save: Callable[[DeviceState], None],
    clock: Callable[[], float],
    tick: float = 0.05,
    eyes: JogEyes | None = None,
    tracks: Calibration | None = None,
) -> str | None:
    """The jog loop: keys, the law, steps through the move journal, the status; until ``q``.

    ``read_keys(timeout)`` waits up to ``timeout`` seconds and returns key names;
    ``show(status)`` draws; ``save(state)`` stores the positions; ``clock()`` is a
    monotonic time in seconds; a tick is ``tick`` s, and a late one moves as two ticks at most
    (no lurch after a stall). Returns the device error that ended the session, if any.
    The device is told to stop when the loop ends, however it ends. With ``eyes`` (a
    camera, :class:`~stickslip.procedures.closed_loop.JogEyes`) the tip is looked at as
    it moves and the positions shown are the seen ones. ``tracks``: the calibration the kept
    tracks were learnt with, when the controller steps with a scaled one
    (:func:`~.move.tracked_calibration`); the controller's by default.
    """
    t_prev = clock()
    tracks = controller.calibration if tracks is None else tracks
    show(controller.status())
    seen: set[int] = set()  # the joints whose track has had the new pose's model error
    try:
        while not controller.quit:
            for key in read_keys(tick):
                controller.press(key, clock())
                if key == "space":
                    dev.stop()
            t = clock()
            # a tick that comes late (a busy machine, a slow device) moves as two ticks at most: after a stall the
            # arm does not lurch by the stall's worth of motion, and the envelope is approached a tick at a time
            steps = controller.tick(t, min(t - t_prev, 2.0 * tick))
            t_prev = t
            for j in (1, 2, 3):
                n = steps[j - 1]
                if n == 0:
                    continue
                pose = state.pose
                q_from = state.positions[j]
                stepper = JointStepper(controller.calibration, state.spec(j), pose)

                def reckon(m: int, stepper: JointStepper = stepper, q_from: float = q_from) -> float:
                    return stepper.position_after(q_from, m)

                source = "dead-reckoned" if exact_positions(dev, state, j) else "assumed"
                assumed = state.sources[j] in ("default", "assumed")
                out = drive(dev, state, j, n, max(abs(n), 1), reckon, save, source)
                controller.sent_steps(j, out.sent)
                if eyes is None and out.error is None and grow_track(  # (a camera's jog keeps its own tracks)
                        state, j, q_from, out.sent, tracks, pose, assumed, seen):
                    save(state)  # the σ grown as a move's (docs/models.md §7)
                if out.error is not None:
                    controller.stop()
                    controller.message = out.error
                    show(controller.status())
                    return out.error
            if eyes is not None:
                _look(eyes, controller, steps)
                t_prev = clock()  # the time spent looking is not moving time: no catch-up burst
            show(controller.status())
    finally:
        try:
            dev.stop()
        except DeviceError:
            pass
    return None


def _look(eyes: JogEyes, controller: JogController, steps: tuple[int, int, int]) -> None:
    """Let the camera look after a tick: the seen positions and corrected step scales go to the jog law."""
    q, why = eyes.after(steps)
    if q is not None:
        controller.q = list(q)
        controller.calibration = eyes.calibration()
        if why:
            controller.message = why
    controller.sources = eyes.sources()


# ---------------------------------------------------------------- the whole session


class KeySource(Protocol):
    """Where a jog session's keys come from (a terminal in raw mode, a script, a web page)."""

    def read(self, timeout: float) -> list[str]:
        """Key names (as :func:`parse_keys` returns them) typed within ``timeout`` seconds."""
        ...

    def close(self) -> None:
        """Give the input back (restore the terminal)."""
        ...


def envelope_stop(
    guard: Guard | None, path: list[list[float]], q_sd: tuple[float, float, float] | SigmaGrowth
) -> str | None:
    """Why a jog tick's path (poses, rad or m) must not be sent: it leaves the rig's envelope; ``None`` if it may."""
    if guard is None or len(path) < 2:
        return None
    try:
        guard.check(path, q_sd)
    except EnvelopeViolation as e:
        return f"stopped at the rig's envelope ({e.refusal.obstacle}): move another way"
    return None


@dataclass(frozen=True)
class JogRequest:
    """A jog session on one device.

    Attributes
    ----------
    device : str
        Controller URL.
    geometry : Geometry
    image_angle : float
        The image frame's turn about z0, rad.
    speed : int
        Speed preset 1-7 (:data:`SPEEDS`).
    max_rate : float
        Most steps per second of any joint (also capped at the controller's frequency).
    hold : float
        Seconds a direction key keeps moving without a repeat (0: until ``space``).
    pose : PoseUpdate
        Positions and tilt to record first.
    max_age_days : int
        A calibration older than this is warned about.
    from_unreferenced : bool
        Steer from joints never referenced (their positions assumed); without it they are
        refused on a real controller. Uncertain joints are always refused.
    trust_calibration : bool
        Use a calibration without its device, or the simulator's, on a real controller.
    camera : CameraLoop or None
        A camera that looks at the tip: the positions shown and kept are the seen ones
        (:class:`~stickslip.procedures.closed_loop.JogEyes`).
    guard : Guard or None
        A rig's envelope: the tip stops at its boundary (:class:`JogController`).
    joints : JointSet or None
        The arm's joints (a rig file's arm: :meth:`stickslip.rig.Arm.joint_specs`); the MM3A's by default.
    stage : Stage or None
        A Cartesian arm's kinematics (:meth:`stickslip.rig.Arm.stage`); keys move its tip in its base frame.
    state_key : str or None
        The key the arm's positions are kept under (:meth:`stickslip.rig.Rig.state_key`); the device's by default.
    """

    device: str
    geometry: kin.Geometry = kin.DEFAULT_GEOMETRY
    image_angle: float = 0.0
    speed: int = 4
    max_rate: float = 1000.0
    hold: float = 0.5
    pose: PoseUpdate = PoseUpdate()
    max_age_days: int = 0
    from_unreferenced: bool = False
    trust_calibration: bool = False
    camera: CameraLoop | None = None
    guard: Guard | None = None
    joints: kin.JointSet | None = None
    stage: kin.Stage | None = None
    state_key: str | None = None


@dataclass(frozen=True)
class JogResult:
    """How a jog session ended: the last status, the kept state, the device error that ended it (if any)."""

    device: str
    status: JogStatus
    state: DeviceState
    error: str | None


def max_rates(dev: Controller, max_rate: float) -> tuple[float, float, float]:
    """Each joint's highest step rate for jogging: the controller's frequency, capped at ``max_rate`` (Hz)."""
    rates = []
    for j in (1, 2, 3):
        try:
            rates.append(min(max_rate, float(dev.frequency(j))))
        except (DeviceError, ValueError, AttributeError):
            rates.append(max_rate)
    return (rates[0], rates[1], rates[2])


def jog(
    store: MoveStore,
    request: JogRequest,
    calibration: Calibration,
    *,
    keys: Callable[[], KeySource],
    show: Callable[[JogStatus], None],
    clock: Callable[[], float] = time.monotonic,
    warn: Callable[[str], None] = lambda _message: None,
    ready: Callable[[], None] = lambda: None,
    opener: Callable[[str], Controller] | None = None,
) -> JogResult:
    """Steer the tip from ``keys()`` until ``q`` (or Ctrl-C), holding the device's lock; positions kept every burst.

    ``calibration`` must model joints 1, 2 and 3 (:class:`~.move.MoveRefused` otherwise,
    or if a joint is uncertain). ``keys()`` is opened once the device is open and closed
    however the session ends; ``show(status)`` draws. Ctrl-C ends the session like ``q``.
    """
    lock = device_key(request.device)
    key = request.state_key or lock
    made_on = calibration_device_problem(calibration, request.device)
    if made_on and not request.trust_calibration:
        raise MoveRefused(made_on)
    with device_lock(store, lock):
        state = referenced_state(store, request.device, request.pose, calibration, request.from_unreferenced,
                                 request.joints, key)
        missing = [j for j in (1, 2, 3) if not _calibrated(calibration, state.spec(j))]
        if missing:
            raise MoveRefused(f"jog steers all three joints, and this calibration has no model of joint(s) {missing}")
        save_state(store, state)
        for w in usage_warnings(calibration, None, request.device, 3, request.max_age_days):
            warn(w)
        ready()
        dev = open_checked(store, request.device, opener or open_device, state,
                           *sharing_controller(store, request.guard))
        keys_in: KeySource | None = None
        eyes: JogEyes | None = None
        try:
            if simulates(dev, state):  # the simulator: start where the positions say
                assert isinstance(dev, PoseSettable)
                dev.set_pose(*state.pose)
            stepping = calibration if request.camera is not None else tracked_calibration(calibration, state)
            ctl = JogController(  # steps with each joint's tracked scale, as a move of it plans (a camera's its own)
                stepping, [state.positions[j] for j in (1, 2, 3)], state.theta, state.psi, request.geometry,
                max_rates(dev, request.max_rate), request.image_angle, request.hold, request.speed - 1,
                guard=request.guard, guard_sd=sigma_growth(state, calibration), joints=request.joints,
                stage=request.stage,
            )

            def save(st: DeviceState) -> None:
                save_state(store, st)

            ctl.mark, ctl.unmark = partial(mark_claim, store, state), partial(release_claim, store, state)
            if request.camera is not None:
                eyes = _open_eyes(store, dev, state, calibration, request, ctl)
            keys_in = keys()
            try:
                error = run_jog(dev, state, ctl, keys_in.read, show, save, clock, eyes=eyes, tracks=calibration)
            except KeyboardInterrupt:
                error = None  # Ctrl-C ends the session like q: the device is stopped, positions kept
        finally:
            if state.claim:  # a tick's claim, however the session ended
                release_claim(store, state)
            if eyes is not None:
                eyes.close()
            if keys_in is not None:
                keys_in.close()
            try:
                dev.close()
            except DeviceError:
                pass
    return JogResult(key, ctl.status(), state, error)


def _calibrated(calibration: Calibration, spec: kin.JointSpec) -> bool:
    """Whether ``calibration`` can step ``spec``: a model of it, or a constant step for a stage's joint."""
    if spec.step_model == "constant":
        return any(j == spec.number for j, _ in calibration.constant_steps)
    return spec.number in calibration.joints


def _open_eyes(
    store: MoveStore, dev: Controller, state: DeviceState, calibration: Calibration, request: JogRequest,
    ctl: JogController,
) -> JogEyes:
    """The session's camera (:class:`~stickslip.procedures.closed_loop.JogEyes`), the jog law on its step scales."""
    from .closed_loop import JogEyes

    assert request.camera is not None
    eyes = JogEyes.open(store, dev, state, calibration, request.camera, request.geometry)
    ctl.calibration = eyes.calibration()
    ctl.sources = eyes.sources()
    return eyes
