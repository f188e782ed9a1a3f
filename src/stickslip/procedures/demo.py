"""The whole story on the simulated MM3A: tune, measure, calibrate, compare, validate, save.

:func:`run_demo` is what ``stickslip demo`` prints. On a fresh
:class:`~stickslip.sim.arm.SimulatedMM3A` it

1. tunes the audio limit switch for each joint from a labelled recording made on
   the simulator (stepping into a stop);
2. runs the paper's 14 calibration traverses (6 of the prismatic joint at
   ``(q2, theta, psi) = (-pi/2, 0, 0), (0, -pi/2, 0), (0, 0, 0)``, 8 of joint 2 over
   its full range at ``(q3, theta, psi) = (0, 0, 0), (12 mm, 0, 0), (12 mm, -pi/2, 0),
   (0, -pi/2, 0)``, each in ``+`` and ``-``), timed by ear with
   :func:`stickslip.procedures.traverse.measure_traverse`;
3. calibrates (:func:`stickslip.calibration.calibrate`) and sets every parameter
   beside the simulator's truth;
4. validates the model against traverses in other poses (model against the
   constant-step comparator, :func:`stickslip.calibration.validate`);
5. saves the measurements (CSV), the validation traverses (CSV), the calibration
   and the tunings (JSON) and a summary (JSON) into a results folder.

Storage hook: pass ``store`` (an object with ``add_traverse(traverse, device=, how=)``
returning an id and ``add_calibration(calibration, device, traverse_ids)``, e.g.
:class:`stickslip.storage.Store`) and every traverse and the calibration are kept
there too; ``on_traverse(result)`` is called after every traverse.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import stat
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from .. import kinematics as kin
from .. import plotting
from ..audio.confirm import CONFIRM_S, check_confirm_s
from ..calibration import (
    PRISMATIC_PAPER_POSES,
    ROTARY_PAPER_POSES,
    Calibration,
    Parameter,
    ValidationResult,
    calibrate,
    validate,
)
from ..clock import check_day_label, today_label
from ..devices.base import device_key
from ..measurements import Traverse, write_measurements
from ..models import JointModel
from ..records import atomic_group, atomic_write_text, writable_target
from ..sim.arm import NOMINAL, SimulatedMM3A
from ..sim.oracle import OracleStopDetector
from ..units import param_scale
from .conditions import conditions_of
from .traverse import TraverseResult, measure_traverse

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = [
    "CALIBRATION_PLAN",
    "VALIDATION_PLAN",
    "REPEAT_PLAN",
    "DemoResult",
    "run_demo",
]

PI = math.pi

MIC_BLOCK = 4096
"""Samples per block of the demo's virtual microphone (85 ms at 48 kHz). The live microphone
reads 1024 (``listen --mic``). The detector's events do not depend on the block size
(``tests/test_audio_blocks.py``), but each block costs a fixed overhead: 4096 makes the demo
1.4-1.6x faster. The joint is then stopped up to 64 ms later. Measured against 1024 (all 38
traverses of seeds 0, 3 and 7): the same counts on seeds 0 and 7; on seed 3, 13 counts moved
by at most 5 steps (0.04 %), its largest parameter error 0.22 -> 0.20 %."""

# (joint, {pose keys}) in the order measured; each pose is traversed + then -.
TraversePlan = tuple[tuple[int, dict[str, float]], ...]
"""Traverses to measure: (joint, pose of the other joints and the tilt), each in + and -."""

CALIBRATION_PLAN: TraversePlan = tuple(
    (3, {"q1": 0.0, "q2": q2, "theta": th, "psi": ps}) for q2, th, ps in PRISMATIC_PAPER_POSES.values()
) + tuple((2, {"q1": 0.0, "q3": q3, "theta": th, "psi": ps}) for q3, th, ps in ROTARY_PAPER_POSES)
"""The paper's calibration poses (Eqs. 4-6 and Fig. 7; their one home is
:mod:`stickslip.calibration.paper`): rad and m."""

VALIDATION_PLAN: TraversePlan = (
    (3, {"q1": 0.0, "q2": -PI / 4, "theta": 0.0, "psi": 0.0}),
    (3, {"q1": 0.0, "q2": -3 * PI / 4, "theta": 0.0, "psi": 0.0}),
    (3, {"q1": 0.0, "q2": -PI, "theta": -PI / 4, "psi": 0.0}),
    (3, {"q1": 0.0, "q2": PI / 6, "theta": 0.0, "psi": PI / 6}),
    (3, {"q1": 0.0, "q2": -PI / 3, "theta": -PI / 4, "psi": -PI / 6}),
    (2, {"q1": 0.0, "q3": 0.006, "theta": 0.0, "psi": 0.0}),
    (2, {"q1": 0.0, "q3": 0.0, "theta": -PI / 4, "psi": 0.0}),
    (2, {"q1": 0.0, "q3": kin.Q3_MAX, "theta": -PI / 4, "psi": 0.0}),
)
"""A sweep of other poses the calibration has not seen (the paper validates joint 2 at
theta = -pi/4); each traversed + then -."""

REPEAT_PLAN: TraversePlan = (
    (3, {"q1": 0.0, "q2": -PI / 2, "theta": 0.0, "psi": 0.0}),
    (2, {"q1": 0.0, "q3": 0.0, "theta": -PI / 2, "psi": 0.0}),
)
"""The paper's ANOVA poses (Section 3.1: no gravity effect on the joint), measured again
``repeats`` times after the calibration so each day has three readings there and
``stickslip anova`` can test day-to-day and + against - differences."""


@dataclass
class DemoResult:
    """Everything the demo did and found.

    Attributes
    ----------
    seed, day : int, str
        The simulator's seed and day label.
    tunings : dict
        ``{joint: Tuning}`` of the limit switch.
    traverses, validation_traverses : list of TraverseResult
        The 14 calibration traverses and the validation sweep.
    repeat_traverses : list of TraverseResult
        Repeats at the paper's ANOVA poses (:data:`REPEAT_PLAN`).
    calibration : Calibration
    validation : ValidationResult or None
    truth : list of Parameter
        The simulator's true parameters (``SimulatedMM3A.true_parameters()``).
    parameters : list of ParameterComparison
        Calibrated parameters beside the truth: ``joint, direction, name, q3, value,
        stderr, true, error, rel_error, unit`` (SI).
    elapsed_s : float
        Wall time of the whole run, s.
    device_s : float
        Time on the simulator's virtual clock, s.
    files : dict
        What was saved where (``measurements``, ``validation``, ``calibration``, ...).
    """

    seed: int
    day: str
    tunings: dict[int, Any]
    traverses: list[TraverseResult]
    validation_traverses: list[TraverseResult]
    calibration: Calibration
    validation: ValidationResult | None
    truth: list[Parameter]
    parameters: list[ParameterComparison]
    elapsed_s: float
    device_s: float
    files: dict[str, str] = field(default_factory=dict)
    steps_simulated: int = 0
    repeat_traverses: list[TraverseResult] = field(default_factory=list)

    def to_dict(self) -> dict[str, object]:
        """The JSON summary (SI units; ``elapsed_s`` in wall-clock seconds)."""
        return {
            "seed": self.seed,
            "day": self.day,
            "elapsed_s": self.elapsed_s,
            "device_s": self.device_s,
            "steps_simulated": self.steps_simulated,
            "method": self.calibration.method,
            "parameters": [p.to_dict() for p in self.parameters],
            "traverses": [_traverse_record(r) for r in self.traverses],
            "validation": {
                "rows": self.validation.rows() if self.validation is not None else [],
                "traverses": [_traverse_record(r) for r in self.validation_traverses],
            },
            "repeats": [_traverse_record(r) for r in self.repeat_traverses],
            "tunings": {str(j): _tuning_dict(t) for j, t in self.tunings.items()},
            "files": dict(self.files),
        }

    def plot(self, ax: Axes | None = None) -> Axes:
        """Error of every calibrated parameter against the truth, % (b: in units of 0.01).

        The shaded band is the acceptance tolerance of each parameter (a, gamma0: 1 %;
        b: 0.01; c, d: 3 %). Returns the matplotlib Axes.
        """
        ax = plotting.axes(ax, (8, 3.5))
        labels, errors, tols = [], [], []
        for p in self.parameters:
            labels.append(p.parameter.label.replace(" (q3=", "\n(q3="))
            errors.append(100 * (p.error if p.parameter.name == "b" else p.rel_error))
            tols.append({"a": 1.0, "gamma0": 1.0, "b": 1.0}.get(p.parameter.name, 3.0))
        x = range(len(labels))
        ax.bar(x, [2 * t for t in tols], bottom=[-t for t in tols], width=0.8, color="0.9", label="tolerance")
        ax.plot(list(x), errors, "o", color="C0", label="calibrated - true")
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xticks(list(x))
        ax.set_xticklabels(labels, rotation=90, fontsize=7)
        ax.set_ylabel("error, % (b: x 0.01)")
        ax.set_title(f"stickslip demo, seed {self.seed}, day {self.day}: calibrated vs true")
        ax.legend(fontsize=8)
        return ax

    def report(self) -> str:
        """A plain-text summary (units labelled)."""
        lines = [
            f"stickslip demo: simulated MM3A, seed {self.seed}, day {self.day}",
            f"{len(self.traverses)} calibration traverses, {len(self.validation_traverses)} "
            f"validation traverses, {self.device_s:.0f} s on the device, "
            f"{self.elapsed_s:.1f} s wall",
            "",
            "parameter         calibrated        true     error",
        ]
        for p in self.parameters:
            scale, unit = param_scale(p.parameter.name, p.parameter.joint)
            lines.append(
                f"{p.parameter.label:<14} {p.parameter.value * scale:>11.4g} {p.true * scale:>11.4g} "
                f"{p.error_text():>9}  {unit}"
            )
        if self.validation is not None:
            lines += [
                "",
                "validation (relative error of the average step):",
                self.validation.report(),
            ]
        if self.files:
            lines += ["", "saved:"] + [f"  {k}: {v}" for k, v in self.files.items()]
        return "\n".join(lines)


def _traverse_record(r: TraverseResult) -> dict[str, object]:
    rec = dict(r.traverse.as_row())
    rec.update(
        gamma=r.gamma,
        commanded_steps=r.commanded_steps,
        steps_after_stop=r.steps_after_stop,
        latency_steps_corrected=r.latency_steps_corrected,
        elapsed_device_s=r.elapsed_device_s,
        retried=r.retried,
    )
    return rec


def _tuning_dict(tuning: Any) -> object:
    to_dict = getattr(tuning, "to_dict", None)
    return to_dict() if callable(to_dict) else repr(tuning)


@dataclass(frozen=True)
class ParameterComparison:
    """A calibrated parameter beside the simulator's true value (SI)."""

    parameter: Parameter
    true: float

    @property
    def error(self) -> float:
        """Calibrated minus true, in the parameter's unit."""
        return self.parameter.value - self.true

    @property
    def rel_error(self) -> float:
        """``error / |true|`` (inf for a true value of 0)."""
        return self.error / abs(self.true) if self.true != 0.0 else math.inf

    def error_text(self) -> str:
        """The error as people read it: absolute for the dimensionless b, else relative (%)."""
        return f"{self.error:+.4f}" if self.parameter.name == "b" else f"{self.rel_error:+.2%}"

    def to_dict(self) -> dict[str, object]:
        """The record of ``demo --json``: the parameter's fields, ``true``, ``error``, ``rel_error``."""
        return {**self.parameter.to_dict(), "true": self.true, "error": self.error, "rel_error": self.rel_error}


def compare_parameters(calibrated: Sequence[Parameter], truth: Sequence[Parameter]) -> list[ParameterComparison]:
    """Calibrated parameters beside the true ones (matched on joint, direction, name and knot)."""
    true_by_key = {t.key: t.value for t in truth}
    return [ParameterComparison(p, true_by_key[p.key]) for p in calibrated if p.key in true_by_key]


class DemoStore(Protocol):
    """What the demo records into (``stickslip.storage.Store`` is one)."""

    def add_traverse(self, t: Traverse, device: str = ..., how: str = ...) -> int: ...

    def add_calibration(self, cal: Calibration, device: str = ..., traverse_ids: Sequence[int] = ...) -> int: ...


@dataclass
class _Runner:
    """Measures the demo's traverses on the simulator, one plan at a time, and records each as it is done."""

    sim: SimulatedMM3A
    detectors: dict[int, Any]
    mic: Any
    bar: _Bars
    day: str
    url: str
    how: str
    burst_steps: int
    listen_from: float
    store: DemoStore | None = None
    on_traverse: Callable[[TraverseResult], None] | None = None
    confirm_s: float = CONFIRM_S

    def run(
        self, plan: TraversePlan, stage: str, prior: Callable[[int, str], JointModel], ids: list[int]
    ) -> list[TraverseResult]:
        """Traverse every (joint, pose) of ``plan`` in + then -; ``prior`` predicts the step count to expect."""
        return [self._one(joint, pose, direction, stage, prior, ids) for joint, pose in plan for direction in "+-"]

    def _one(
        self,
        joint: int,
        pose: dict[str, float],
        direction: str,
        stage: str,
        prior: Callable[[int, str], JointModel],
        ids: list[int],
    ) -> TraverseResult:
        spec = kin.JOINTS[joint]
        start, end = (spec.lower, spec.upper) if direction == "+" else (spec.upper, spec.lower)
        if direction == "+":  # the experimenter sets the pose; the joint rests on its start stop
            self.sim.set_pose(**{**pose, f"q{joint}": start})
        self.bar.stage(f"{stage}: joint {joint} {direction}")
        expected = spec.span / float(prior(joint, direction).average_gamma(start, end, *self.sim.pose))
        r = measure_traverse(
            self.sim,
            joint,
            direction,
            detector=self.detectors[joint],
            audio_blocks=self.mic,
            pose=self.sim.pose,
            day=self.day,
            burst_steps=self.burst_steps,
            progress=self.bar.traverse_callback(),
            expected_steps=int(expected),
            listen_after_steps=int(self.listen_from * expected),
            confirm_s=self.confirm_s,
        )
        if self.store is not None:  # one transaction per traverse: a kill loses at most this one
            ids.append(self.store.add_traverse(r.traverse, device=device_key(self.url), how=self.how))
        self.bar.advance()
        if self.on_traverse is not None:
            self.on_traverse(r)
        return r


def _check_arguments(listen_from: float, switch: str, repeats: int, out: str | Path | None) -> None:
    """Refuse bad demo options before any work, and make the results folder."""
    if not 0.0 <= listen_from <= 0.95:
        raise ValueError(f"listen_from = {listen_from!r} is outside [0, 0.95]")
    if switch not in ("audio", "oracle"):
        raise ValueError(f"switch must be 'audio' or 'oracle', got {switch!r}")
    if not (isinstance(repeats, int) and 0 <= repeats <= 10):
        raise ValueError(f"repeats = {repeats!r} is outside [0, 10]")
    if out is not None:  # fail before the work, not after it
        try:
            Path(out).mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise OSError(f"cannot use {str(out)!r} as the results folder: {e.strerror or e}") from e


def _limit_switches(sim: SimulatedMM3A, switch: str, bar: _Bars) -> tuple[dict[int, Any], dict[int, Any], Any]:
    """Tunings, detectors and microphone per joint: tuned from labelled recordings, or the oracle."""
    if switch != "audio":
        return {}, {j: OracleStopDetector(sim, j, delay_s=0.03) for j in (1, 2, 3)}, sim.microphone(silent=True)
    from ..audio.detector import detector_for
    from ..audio.tuning import tune

    tunings: dict[int, Any] = {}
    detectors: dict[int, Any] = {}
    for joint in (1, 2, 3):
        bar.stage(f"tuning the limit switch of joint {joint}")
        samples, rate, stop_at = sim.labelled_recording(joint, "+", before_s=2.0, after_s=1.0)
        tunings[joint] = tune(samples, rate, stop_at, joint=joint, step_rate_hz=sim.frequency(joint))
        detectors[joint] = detector_for(tunings[joint], sim.clock_s)
    return tunings, detectors, sim.microphone(MIC_BLOCK)


def _simulator(
    seed: int, day: str, step_noise: float, soundscape_kwargs: dict[str, Any] | None, physics: bool
) -> tuple[SimulatedMM3A, str]:
    """The demo's simulated arm (the physics-based one if ``physics``) and its URL."""
    url = f"sim://?seed={seed}&day={day}" + ("&physics=1" if physics else "")
    if physics:
        from ..sim.physics import PhysicsMM3A

        sim: SimulatedMM3A = PhysicsMM3A(
            seed=seed, day=day, step_noise=step_noise, soundscape_kwargs=soundscape_kwargs, url=url
        )
    else:
        sim = SimulatedMM3A(seed=seed, day=day, step_noise=step_noise, soundscape_kwargs=soundscape_kwargs, url=url)
    return sim, url


def run_demo(
    seed: int = 0,
    day: str | None = None,
    out: str | Path | None = "stickslip-results",
    *,
    progress: bool | Callable[[str, int, int], None] = False,
    on_traverse: Callable[[TraverseResult], None] | None = None,
    store: DemoStore | None = None,
    validation: bool = True,
    burst_steps: int = 1000,
    step_noise: float = 0.03,
    soundscape_kwargs: dict[str, Any] | None = None,
    switch: str = "audio",
    listen_from: float = 0.8,
    repeats: int = 2,
    physics: bool = False,
    confirm_s: float = CONFIRM_S,
) -> DemoResult:
    """Run the whole calibration story on a simulated MM3A and return what happened.

    Parameters
    ----------
    seed : int
        Simulator seed (drift of the true parameters, step noise, room sound).
    day : str, optional
        Session label; the true parameters drift with it. Default: today's ISO date.
    out : path or None
        Results folder (created); ``None`` saves nothing.
    progress : bool or callable
        ``True`` shows rich progress bars on stderr; a callable gets
        ``(stage, done, total)`` after every traverse.
    on_traverse : callable, optional
        Called with every :class:`~stickslip.procedures.traverse.TraverseResult` as it is measured.
    store : DemoStore, optional
        Keeps every traverse and the calibration (see the module docstring).
    validation : bool
        Measure and evaluate the validation sweep (:data:`VALIDATION_PLAN`).
    burst_steps : int
        Steps per burst of the traverse procedure.
    step_noise : float
        Relative per-step noise of the simulator.
    soundscape_kwargs : dict, optional
        Room sound options for the simulator's microphone.
    switch : {"audio", "oracle"}
        The limit switch: the tuned audio detector on the virtual microphone
        (default), or :class:`~stickslip.sim.oracle.OracleStopDetector`, which
        knows the true stops (no sound rendered; for fast tests).
    repeats : int
        After the calibration, measure the paper's ANOVA poses (:data:`REPEAT_PLAN`)
        this many more times in each direction, so the day has three readings there.
    physics : bool
        Run on the physics-based arm (:class:`~stickslip.sim.physics.PhysicsMM3A`,
        ``sim://?physics=1``) instead of the closed-form one; it has no true Eq. 3/8
        parameters, so the summary compares with none.
    confirm_s : float
        With the audio switch, take a stop only once it persisted this long, s
        (:func:`~stickslip.procedures.traverse.measure_traverse`; 0: the first fire).
    listen_from : float
        Start listening after this fraction of the step count predicted by the
        previous calibration (for the calibration traverses: the nominal parameters
        :data:`~stickslip.sim.arm.NOMINAL`, standing in for yesterday's
        calibration; for the validation sweep: today's). The stop cannot come much
        earlier; if it does, :func:`~stickslip.procedures.traverse.measure_traverse` measures
        again listening all along. 0 listens from the start. In [0, 0.95].
    """
    _check_arguments(listen_from, switch, repeats, out)
    check_confirm_s(confirm_s)
    t_wall = time.perf_counter()
    day = check_day_label(day) if day is not None else today_label()
    sim, url = _simulator(seed, day, step_noise, soundscape_kwargs, physics)
    n_val = 2 * len(VALIDATION_PLAN) if validation else 0
    bar = _Bars(progress, 2 * len(CALIBRATION_PLAN) + n_val + 2 * len(REPEAT_PLAN) * repeats)
    try:
        tunings, detectors, mic = _limit_switches(sim, switch, bar)
        how = "simulated, audio switch" if switch == "audio" else "simulated, oracle switch"
        runner = _Runner(
            sim, detectors, mic, bar, day, url, how, burst_steps, listen_from, store, on_traverse, confirm_s
        )

        def nominal(joint: int, direction: str) -> JointModel:
            return JointModel(joint, direction, NOMINAL[(joint, direction)])

        cal_ids: list[int] = []
        traverses = runner.run(CALIBRATION_PLAN, "calibration", nominal, cal_ids)
        rows = [r.traverse for r in traverses]
        cal = dataclasses.replace(calibrate(rows, day=day, source=url), conditions=conditions_of(sim, url))
        if store is not None:
            store.add_calibration(cal, device_key(url), cal_ids)
        truth = sim.true_parameters()
        parameters = compare_parameters(cal.parameters(), truth)
        val_results: list[TraverseResult] = []
        val: ValidationResult | None = None
        if validation:
            val_results = runner.run(VALIDATION_PLAN, "validation", cal.model, [])
            val = validate(cal, [r.traverse for r in val_results])
        rep_results = runner.run(REPEAT_PLAN * repeats, "repeats for the ANOVA", cal.model, [])
    finally:
        bar.close()

    result = DemoResult(
        seed=seed,
        day=day,
        tunings=tunings,
        traverses=traverses,
        validation_traverses=val_results,
        repeat_traverses=rep_results,
        calibration=cal,
        validation=val,
        truth=truth,
        parameters=parameters,
        elapsed_s=0.0,
        device_s=sim.clock_s,
        steps_simulated=sim.steps_simulated,
    )
    if store is not None:
        result.files["store"] = str(getattr(store, "path", "store"))
    if out is None:
        result.elapsed_s = time.perf_counter() - t_wall
        return result
    with atomic_group():  # every results file or none: a disk full half-way leaves an earlier run's whole
        result.files.update(save_results(result, out))
        result.elapsed_s = time.perf_counter() - t_wall
        _write_summary(result, Path(out))
    return result


def save_results(result: DemoResult, out: str | Path) -> dict[str, str]:
    """Save measurements (CSV), validation traverses (CSV), calibration and tunings (JSON)."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}
    path = folder / "measurements.csv"
    write_measurements(path, [r.traverse for r in result.traverses])
    files["measurements"] = str(path)
    if result.validation_traverses:
        path = folder / "validation.csv"
        write_measurements(path, [r.traverse for r in result.validation_traverses])
        files["validation"] = str(path)
    if result.repeat_traverses:
        path = folder / "repeats.csv"
        write_measurements(path, [r.traverse for r in result.repeat_traverses])
        files["repeats"] = str(path)
    path = folder / "calibration.json"
    result.calibration.save(path)
    files["calibration"] = str(path)
    for joint, tuning in result.tunings.items():
        path = folder / f"tuning-joint{joint}.json"
        save = getattr(tuning, "save", None)
        if callable(save):
            save(path)
        else:
            atomic_write_text(path, json.dumps(_tuning_dict(tuning), indent=2) + "\n")
        files[f"tuning_joint{joint}"] = str(path)
    files["summary"] = str(folder / "summary.json")
    return files


_OUTPUTS = ("measurements.csv", "validation.csv", "repeats.csv", "calibration.json", "tuning-joint1.json",
            "tuning-joint2.json", "tuning-joint3.json", "summary.json")  # fmt: skip


def check_outputs(out: str | Path) -> None:
    """Refuse (``ValueError`` naming it) a results file of ``out`` that cannot be replaced by a file (a folder, a FIFO),
    before the demo runs: found at the end, it left the files written before it replaced and the rest not."""
    try:
        st = os.stat(out)
    except FileNotFoundError:
        return  # a folder still to make
    except OSError as e:  # a name too long for the file system, a loop of links: raised by is_dir on 3.11
        raise ValueError(f"{out}: cannot make the results folder ({e.strerror or e}); nothing was run") from None
    if not stat.S_ISDIR(st.st_mode):
        return  # a file in its way: the run says so when it makes it
    for name in _OUTPUTS:
        writable_target(Path(out) / name, "results")


def left_from_earlier(result: DemoResult, out: str | Path) -> list[Path]:
    """The files of ``out`` named as a demo's results that this run did not write (an earlier run's, kept as they
    were: ``--no-validation`` writes no validation.csv), which a reader would take for this run's."""
    written = {Path(f).name for f in result.files.values()}
    return [Path(out) / n for n in _OUTPUTS if n not in written and (Path(out) / n).is_file()]


def _write_summary(result: DemoResult, folder: Path) -> None:
    def clean(o: object) -> object:
        if isinstance(o, float):
            return o if math.isfinite(o) else None
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        return o

    atomic_write_text(folder / "summary.json", json.dumps(clean(result.to_dict()), indent=2) + "\n")


class _Bars:
    """Progress for the demo: an overall bar over traverses and one for the traverse in flight."""

    def __init__(self, progress: bool | Callable[[str, int, int], None], total: int):
        self.total = total
        self.done = 0
        self.callback = progress if callable(progress) else None
        self._label = ""
        self._bar = None
        if progress is True:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
            )

            self._bar = Progress(
                TextColumn("{task.description:<40}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[info]}"),
                TimeElapsedColumn(),
                console=Console(stderr=True),
                transient=True,
            )
            self._bar.start()
            self._overall = self._bar.add_task("traverses", total=total, info="")
            self._current = self._bar.add_task("", total=None, info="")

    def stage(self, label: str) -> None:
        self._label = label
        if self._bar is not None:
            self._bar.update(self._current, description=label, completed=0, info="")

    def traverse_callback(self) -> Callable[[int, float], None]:
        def update(steps: int, device_s: float) -> None:
            if self._bar is not None:
                self._bar.update(self._current, completed=steps, info=f"{device_s:5.1f} s on the device")

        return update

    def advance(self) -> None:
        self.done += 1
        if self._bar is not None:
            self._bar.update(self._overall, completed=self.done)
        if self.callback is not None:
            self.callback(self._label, self.done, self.total)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
