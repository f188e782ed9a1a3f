"""Planning moves with a calibration: steps for a move, and dead reckoning after N steps.

The number of steps to move rotary joint ``j`` from ``q`` to ``q'`` is the exact
integral ``integral_q^q' dq / gamma(q)`` (the step size changes along the way as the
gravity torque changes), rounded to the nearest integer. The prismatic joint's step
does not depend on its own position, so there it is ``|q' - q| / gamma``.

Dead reckoning is the inverse: where the joint ends after ``N`` steps. A plan and its
dead reckoning agree to within half a step (the rounding).

The hot path is built for teleoperation loops at 1 kHz: :class:`Planner` precomputes
the step-size coefficients of a joint in a pose, and :meth:`Planner.steps` then costs
a few microseconds (pure ``math``, no numpy). :func:`plan_move` is the one-call form.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from .. import kinematics as kin
from ..calibration import Calibration
from ..measurements import check_pose
from ..models import JointModel, PrismaticParams, StepProfile, direction_label
from ..models.families import FamilyModel, TabulatedProfile

__all__ = ["MovePlan", "Planner", "plan_move", "dead_reckon"]

@dataclass(frozen=True)
class MovePlan:
    """A planned move of one joint.

    Attributes
    ----------
    joint : int
    direction : str
        ``"+"`` or ``"-"``.
    steps : int
        Number of steps to command (>= 0; the sign is in ``direction``).
    q_from, q_to : float
        Requested start and target (rad or m).
    q_end_predicted : float
        Where the joint is predicted to end after ``steps`` (rad or m); within half a
        step of ``q_to``.
    exact_steps : float
        The unrounded integral.
    gamma_start, gamma_end : float
        Predicted step size at the start and at the target (rad or m).
    spec : JointSpec or None
        The arm's joint when it is not the MM3A's (its kind and unit); ``None``: the MM3A's.
    """

    joint: int
    direction: str
    steps: int
    q_from: float
    q_to: float
    q_end_predicted: float
    exact_steps: float
    gamma_start: float
    gamma_end: float
    spec: kin.JointSpec | None = None

    @property
    def signed_steps(self) -> int:
        """Steps with the direction's sign (what a controller's ``step(joint, n)`` takes)."""
        return self.steps if self.direction == "+" else -self.steps

    def __repr__(self) -> str:
        from ..units import format_position, format_step

        j = self.spec or self.joint
        return (
            f"MovePlan(joint {self.joint}: {format_position(self.q_from, j)} -> {format_position(self.q_to, j)}, "
            f"{self.signed_steps:+d} steps, predicted end {format_position(self.q_end_predicted, j)}, "
            f"step {format_step(self.gamma_start, j)} -> {format_step(self.gamma_end, j)})"
        )

    def _repr_html_(self) -> str:
        """The plan as a one-row table (positions in µm or deg, steps in nm or µrad), for Jupyter."""
        from ..notebook import html_table
        from ..units import position_scale, step_scale

        k, pu = position_scale(self.spec or self.joint)
        s, su = step_scale(self.spec or self.joint)
        return html_table(
            f"move of joint {self.joint}",
            ["steps", f"from ({pu})", f"to ({pu})", f"predicted end ({pu})", f"step at start ({su})",
             f"step at target ({su})"],
            [[f"{self.signed_steps:+d}", f"{self.q_from * k:.6g}", f"{self.q_to * k:.6g}",
              f"{self.q_end_predicted * k:.6g}", f"{self.gamma_start * s:.5g}", f"{self.gamma_end * s:.5g}"]],
        )

    def as_dict(self) -> dict[str, object]:
        return {
            "joint": self.joint,
            "direction": self.direction,
            "steps": self.steps,
            "signed_steps": self.signed_steps,
            "from": self.q_from,
            "to": self.q_to,
            "end_predicted": self.q_end_predicted,
            "exact_steps": self.exact_steps,
            "gamma_start": self.gamma_start,
            "gamma_end": self.gamma_end,
            "unit": kin.joint_spec(self.spec or self.joint).unit,
        }


def _scalar_coefficients(model: JointModel, pose: kin.Pose) -> tuple[float, float, float]:
    """``(A, alpha, beta)`` of ``model`` in ``pose``, with ``math`` (the planner's hot path).

    The same numbers as :meth:`JointModel.rotary_coefficients` (a test checks it), without
    numpy's per-call overhead on scalars.
    """
    q1, q2, q3, th, ps = pose
    ct = math.cos(th)
    gx, gy, gz = ct * math.sin(ps), -math.sin(th), -ct * math.cos(ps)  # gravity_base
    p = model.params
    if isinstance(p, PrismaticParams):
        gx1 = math.cos(q1) * gx + math.sin(q1) * gy  # gravity in the frame turned by q1
        load = math.sin(q2) * gx1 - math.cos(q2) * gz  # prismatic_load
        return (1.0 - p.b * abs(math.cos(q2))) * (p.a - p.c * load), 0.0, 0.0
    k0, k1 = p.knots
    w = (q3 - k0) / (k1 - k0)
    g0 = p.gamma0[0] + (p.gamma0[1] - p.gamma0[0]) * w
    d = p.d[0] + (p.d[1] - p.d[0]) * w
    if model.joint == 2:
        al, be = math.cos(q1) * gx + math.sin(q1) * gy, gz
    else:
        reach = -math.sin(q2)
        al, be = reach * math.sin(th), reach * ct * math.sin(ps)
    return g0, d * al, d * be


class Planner:
    """Plans moves of one joint in one pose; build once, call :meth:`steps` many times.

    Parameters
    ----------
    calibration : Calibration
    joint : int or JointSpec
        1, 2 or 3 of the MM3A, or an arm's own joint (:meth:`stickslip.rig.Arm.joint_specs`).
        A joint whose ``step_model`` is ``"constant"`` (an ``xyz`` arm's stage) is planned
        with the calibration's constant step of each direction; the pose does not enter.
        A calibration that models such a joint the MM3A's way, or whose steps of it are of
        another kind (in rad for a prismatic stage: :meth:`Calibration.kind`), is refused
        (``ValueError``): its steps are another arm's (an MM3A's joint 1 in rad, not a stage's in m).
    pose : Pose or sequence of 5 float
        The other joints and the tilt (q1, q2 rad, q3 m, theta, psi rad); the joint's own
        coordinate in it is ignored.

    Examples
    --------
    >>> planner = Planner(cal, 3, Pose(q2=-math.pi / 2))      # doctest: +SKIP
    >>> planner.steps(0.0, 30e-6)                              # doctest: +SKIP
    31
    >>> planner.steps(30e-6, 0.0)                              # doctest: +SKIP
    -32
    """

    def __init__(self, calibration: Calibration, joint: int | kin.JointSpec, pose: kin.Pose | Sequence[float]):
        self.spec = kin.joint_spec(joint)
        self.joint = self.spec.number
        # |q| beyond a full turn (rotary) or a metre (prismatic) is no joint's position: degrees, or mm as m
        self._bound = self.spec.bound
        if not isinstance(pose, kin.Pose):  # [0, -1, 0] was "zip() argument 2 is shorter than argument 1"
            if len(pose) != len(kin.Pose._fields):
                raise ValueError(f"pose = {pose!r}: a Pose or its five numbers (q1, q2 rad, q3 m, theta, psi rad)")
            pose = kin.Pose(*pose)
        self.pose = pose
        self._coeffs: dict[int, StepProfile | TabulatedProfile] = {}  # per direction, made on first use
        if self.spec.step_model == "constant":  # a stage: the calibration's constant step of each direction
            if any(j == self.joint for j, _ in calibration.models):  # an MM3A's: its steps are not a stage's
                raise ValueError(
                    f"this calibration models joint {self.joint} as an MM3A's (the paper's load terms), and this "
                    "joint is a stage's, planned with a constant step: give the stage's own calibration"
                )
            if calibration.kind(self.joint) != self.spec.kind:  # its steps in rad for a stage's metres, or back
                raise ValueError(
                    f"this calibration's steps of joint {self.joint} are in {calibration.unit(self.joint)} (a "
                    f"{calibration.kind(self.joint)} joint's), and this joint is {self.spec.kind}: give the stage's "
                    "own calibration (stickslip calibrate TABLE --rig RIG --arm NAME)"
                )
            self._models: dict[int, JointModel] = {}
            for s, lab in ((1, "+"), (-1, "-")):
                step = calibration.constant_steps.get((self.joint, lab))
                if step is not None:
                    if not (math.isfinite(step) and step > 0):
                        raise ValueError(f"joint {self.joint}{lab}: the calibration's constant step {step!r} "
                                         "is not a positive number")
                    self._coeffs[s] = StepProfile(step)
            if not self._coeffs:
                raise KeyError(f"joint {self.joint} has no constant step in this calibration")
            return
        problems = check_pose(self.joint, dict(zip(kin.Pose._fields, map(float, pose), strict=True)))
        if problems:  # a pose the arm cannot take is never planned in
            raise ValueError(f"pose for a move of joint {self.joint}: " + "; ".join(problems))
        models = calibration.models
        self._models = {s: models[(self.joint, lab)] for s, lab in ((1, "+"), (-1, "-")) if (self.joint, lab) in models}
        if not self._models:
            raise KeyError(f"joint {self.joint} is not in this calibration")

    def _dir(self, sign: int) -> StepProfile | TabulatedProfile:
        c = self._coeffs.get(sign)
        if c is not None:
            return c
        m = self._models.get(sign)
        if m is None:
            raise KeyError(f"joint {self.joint} direction {direction_label(sign)} is not in this calibration")
        if isinstance(m, FamilyModel):  # a family beyond the paper's: its own profile along the travel
            c = self._coeffs[sign] = m.profile(self.pose)
        else:
            c = self._coeffs[sign] = StepProfile(*_scalar_coefficients(m, self.pose))
        return c

    def _unit_slip(self, **qs: float) -> ValueError:
        """The error for a position that is not finite or beyond a full turn / a metre (the hot path's one check)."""
        for name, q in qs.items():
            if not math.isfinite(q):
                return ValueError(f"{name} = {q!r} must be a finite position in {self.spec.unit}")
            if abs(q) > self._bound:
                what = "a full turn: radians, not degrees" if self.spec.rotary else "a metre: metres, not mm or µm"
                return ValueError(f"{name} = {q:.6g} {self.spec.unit} is more than {what} (joint {self.joint})")
        return ValueError(f"positions {qs!r}")  # (not reached: called only when one is out)

    def _check_range(self, q: float, what: str) -> None:
        problem = self.spec.range_problem(what, q)
        if problem:
            raise ValueError(problem)

    def exact_steps(self, q_from: float, q_to: float) -> float:
        """The unrounded number of steps from ``q_from`` to ``q_to`` (>= 0)."""
        b = self._bound
        if not (-b <= q_from <= b and -b <= q_to <= b):
            raise self._unit_slip(q_from=q_from, q_to=q_to)
        if q_to == q_from:
            return 0.0
        sign = 1 if q_to > q_from else -1
        return (self._coeffs.get(sign) or self._dir(sign)).steps(q_from, q_to)

    def steps(self, q_from: float, q_to: float) -> int:
        """Signed steps to command to move from ``q_from`` to ``q_to``: negative when ``q_to < q_from``.

        The sign is the direction (docs/design.md §2), so the result can be handed to
        :meth:`position_after` or to a controller's ``step`` as it is. Not range-checked (the hot
        path: :meth:`plan` checks the stops), but a position beyond a full turn (rotary, rad) or a
        metre (prismatic, m), or not finite, raises ``ValueError``: -60 meant as degrees gave 139624 steps.
        """
        b = self._bound
        if not (-b <= q_from <= b and -b <= q_to <= b):
            raise self._unit_slip(q_from=q_from, q_to=q_to)
        if q_to == q_from:
            return 0
        sign = 1 if q_to > q_from else -1
        return sign * round((self._coeffs.get(sign) or self._dir(sign)).steps(q_from, q_to))  # the hot path

    def gamma(self, q: float, direction: str | int) -> float:
        """Predicted step size at ``q`` in ``direction`` (rad or m)."""
        from ..models import direction_sign

        return self._dir(direction_sign(direction)).gamma(q)

    def position_after(self, q_start: float, signed_steps: int | float) -> float:
        """Dead reckoning: where the joint is after ``signed_steps`` steps from ``q_start`` (checked as ``steps``)."""
        if not -self._bound <= q_start <= self._bound:
            raise self._unit_slip(q_start=q_start)
        if signed_steps == 0:
            return float(q_start)
        sign = 1 if signed_steps > 0 else -1
        return self._dir(sign).inverse(float(q_start), float(abs(signed_steps)), sign)

    def plan(self, q_from: float, q_to: float, check_range: bool = True) -> MovePlan:
        """A full :class:`MovePlan` (with the dead-reckoned end point)."""
        if check_range:
            self._check_range(q_from, "start")
            self._check_range(q_to, "target")
        sign = 1 if q_to >= q_from else -1
        c = self._dir(sign)
        exact = 0.0 if q_to == q_from else c.steps(q_from, q_to)
        n = round(exact)
        end = self.position_after(q_from, sign * n)  # exactly what dead_reckon gives for these steps
        return MovePlan(
            self.joint, direction_label(sign), n, float(q_from), float(q_to), end, exact, c.gamma(q_from),
            c.gamma(q_to), None if self.spec is kin.joint_spec(self.joint) else self.spec,
        )


def plan_move(calibration: Calibration, joint: int, q_from: float, q_to: float, pose: kin.Pose) -> MovePlan:
    """Plan a move of ``joint`` from ``q_from`` to ``q_to`` (rad or m) in ``pose``.

    Raises ``ValueError`` if either end is outside the joint's range, ``KeyError`` if
    the calibration lacks that joint/direction.
    """
    return Planner(calibration, joint, pose).plan(q_from, q_to)


def dead_reckon(calibration: Calibration, joint: int, q_start: float, signed_steps: int, pose: kin.Pose) -> float:
    """Where ``joint`` ends after ``signed_steps`` steps from ``q_start`` in ``pose`` (rad or m)."""
    return Planner(calibration, joint, pose).position_after(q_start, signed_steps)
