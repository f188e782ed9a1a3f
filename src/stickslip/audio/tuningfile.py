"""A tuning: how to hear one joint's end stop, and its JSON file (``kind: stickslip.audio.Tuning``).

Version 2 holds the spectral-template detector's settings (:mod:`stickslip.audio.change`),
version 1 the band-power detector's (:mod:`stickslip.audio.comparators.band`); both load.
Units are in the key names.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import records
from ..units import khz_slip
from .paramfield import param

__all__ = ["TUNING_FILE", "Tuning", "TuningFileError", "TuningFileParams", "default_frame"]

_KIND = "stickslip.audio.Tuning"
_CONTINUUM = ("continuum_levels_db", "continuum_signature_db", "continuum_spread_db")
_FINE = ("fine_start_hz", "fine_bin_hz", "fine_stepping_db", "fine_stopped_db")


@dataclass(frozen=True)
class TuningFileParams:
    """What a tuning file may hold, and when its step rate is too far from the one heard."""

    step_rate_tolerance: float = param(
        0.05,
        "of the tuning's rate",
        "farther, listen and traverse warn: 17 of 288 stops missed or late at 6-8 % off, none within 4 %",
    )
    fine_max: int = param(20_000, "levels", "at most this many levels in each fine spectrum (20 kHz is 3400)")
    sample_rate_range: tuple[int, int] = param(
        (2_000, 192_000),
        "Hz",
        "an accelerometer bridge sends 3.2-5 kHz (stepping under 1 kHz); a sound card up to 192 kHz",
    )

    def rate_problem(self, sample_rate: float) -> str | None:
        """Why ``sample_rate`` (Hz) cannot be tuned or heard at, or None."""
        lo, hi = self.sample_rate_range
        if lo <= sample_rate <= hi:
            return None
        return f"sample rate {sample_rate:g} Hz is outside {lo}-{hi} Hz{khz_slip(sample_rate, lo, hi)}"


TUNING_FILE = TuningFileParams()


class TuningFileError(ValueError):
    """A tuning file or dictionary that cannot be used (names the key and the reason)."""


def default_frame(sample_rate: int) -> int:
    """Frame length in samples: the power of two closest to 10.7 ms (512 at 48 kHz)."""
    return int(2 ** round(math.log2(sample_rate * 512 / 48_000)))


def _number(name: str, v: Any) -> float:
    """:func:`stickslip.records.finite_number`, raising :class:`TuningFileError`."""
    try:
        return records.finite_number(v, name)
    except ValueError as e:
        raise TuningFileError(str(e)) from None


@dataclass(frozen=True)
class Tuning:
    """How to hear one joint's end stop.

    Parameters
    ----------
    band_hz : (float, float)
        Lower and upper edge of the band whose power is watched, Hz.
    threshold_db : float
        Band level at or above which a frame counts as "stop", dBFS.
    sample_rate : int
        Sample rate the tuning was made for, Hz.
    frame : int
        Frame length, samples (Hann window, rfft).
    hop : int
        Hop between frames, samples.
    hold_s : float
        How long the level must stay above threshold before the event fires, s.
    hysteresis_db : float
        The level must fall this far below threshold to re-arm, dB.
    release_s : float
        ... for this long, s.
    max_dips : int
        Frames below threshold tolerated within the hold: the event fires when
        ``hold_frames`` of the last ``hold_frames + max_dips`` frames were above.
    onset_lag_s : float
        Time from the true onset of the stop to the interpolated threshold crossing, s
        (measured by :func:`stickslip.audio.tuning.tune`); used for ``onset_s``.
    joint : int or None
        Joint the tuning belongs to (informational).
    contrast_db, margin_db, stepping_db, stopped_db : float or None
        What tuning saw: stopped-part low percentile minus stepping-part high percentile,
        threshold minus stepping high percentile, and those two levels (dBFS).
    latency_measured_s : float or None
        detected_at - stop onset on the tuning recording, s.
    reference_hz : (float, float) or None
        ``"band"`` method: the band level is taken relative to this band's, Hz.
    method : str
        ``"template"``: the spectral-template change detector (:mod:`stickslip.audio.change`; what
        :func:`~stickslip.audio.tuning.tune` makes). ``"band"``: the band-power detector
        of tuning files version 1 (band level against ``threshold_db``).
    edges_hz : tuple of float
        ``"template"``: sub-band edges, Hz (``band_hz`` is their span).
    signature_db : tuple of float
        ``"template"``: the stop's departure from stepping per sub-band, dB.
    spread_db : tuple of float
        ``"template"``: frame-to-frame spread of stepping per sub-band, dB.
    residual_max : float
        ``"template"``: largest residual (in spreads) a frame may have and still count.
    decay_ratio : float
        ``"template"``: the firing frame's stop-likeness must be at least this fraction
        of the largest in the hold window (a decaying transient is not a stop).
    tau_s : float
        ``"template"``: time constant of the running stepping template, s.
    warmup_s : float
        ``"template"``: stepping heard before the detector can fire, s.
    trim : int
        ``"template"``: sub-bands dropped from each frame's fit (those that fit worst).
    stepping_levels_db : tuple of float or None
        ``"template"``: stepping's level per sub-band in the tuning recording, dBFS; lets the
        detector tell that it began listening at the stop (see :mod:`stickslip.audio.change.start`).
    drop_threshold : (float, float) or None
        ``"template"``: the broad and the local drop below the stepping template at which
        a frame counts as a stop whatever its signature (spreads, see
        :class:`~stickslip.audio.change.drops.DropMeter`); None: only the tuned signature counts.
    step_rate_hz : float or None
        ``"template"``: the step rate heard in the tuning recording, Hz (None in files made
        before it was recorded: the detector then behaves as before).
    continuum_levels_db, continuum_signature_db, continuum_spread_db : tuple of float or None
        ``"template"``, with ``step_rate_hz``: per sub-band, the stepping's level of the
        continuum between the step clock's lines (dB, a power per frequency bin), the stop's
        departure from it (dB) and its frame-to-frame spread (dB); NaN (``null`` in the
        file) where a sub-band has no bin off the lines at the tuning's rate
        (:func:`~stickslip.audio.features.spectra.continuum_levels_db`). They let the detector tell
        that it began listening at the stop when the stream steps at another rate.
    fine_start_hz, fine_bin_hz : float or None
        ``"template"``: the first bin's frequency and the bin width
        of the two fine spectra below, Hz.
    fine_stepping_db, fine_stopped_db : tuple of float or None
        ``"template"``, used with ``step_rate_hz``: the tuning recording's fine continuum
        spectra (Welch, ~5.9 Hz bins, the step clock's lines interpolated across; dB re
        full scale per Hz) of stepping and of the stop, over the sub-bands and a few bins
        beyond (:func:`~stickslip.audio.features.fine.fine_spectrum_db`). They let the
        detector predict the stop's signature at another step rate
        (:class:`~stickslip.audio.features.fine.SignaturePredictor`); None in files made
        before they were recorded (the detector then fits the tuned signature alone).
    per_octave : float or None
        ``"template"``: sub-bands per octave that :func:`~stickslip.audio.tuning.tune` chose
        for ``edges_hz`` (3, or finer for a stop that only shifts the spectrum); None in
        files made before it was recorded. Informational: ``edges_hz`` are the sub-bands.
    checks : dict or None
        What :func:`~stickslip.audio.tuning.tune` verified (false alarms per hour with
        interference injected, latency); informational.

    Notes
    -----
    For ``"template"`` tunings ``threshold_db`` is the threshold on the stop-likeness
    (0 stepping, 1 the tuned stop; dimensionless) and ``hysteresis_db`` its hysteresis.
    """

    band_hz: tuple[float, float]
    threshold_db: float
    sample_rate: int = 48_000
    frame: int = 512
    hop: int = 128
    hold_s: float = 0.016
    hysteresis_db: float = 6.0
    release_s: float = 0.25
    max_dips: int = 2
    onset_lag_s: float = 0.003
    joint: int | None = None
    contrast_db: float | None = None
    margin_db: float | None = None
    stepping_db: float | None = None
    stopped_db: float | None = None
    latency_measured_s: float | None = None
    reference_hz: tuple[float, float] | None = None
    method: str = "band"
    edges_hz: tuple[float, ...] | None = None
    signature_db: tuple[float, ...] | None = None
    spread_db: tuple[float, ...] | None = None
    residual_max: float = 4.0
    decay_ratio: float = 0.5
    tau_s: float = 0.5
    warmup_s: float = 0.15
    trim: int = 0
    stepping_levels_db: tuple[float, ...] | None = None
    drop_threshold: tuple[float, float] | None = None
    step_rate_hz: float | None = None
    continuum_levels_db: tuple[float, ...] | None = None
    continuum_signature_db: tuple[float, ...] | None = None
    continuum_spread_db: tuple[float, ...] | None = None
    per_octave: float | None = None
    fine_start_hz: float | None = None
    fine_bin_hz: float | None = None
    fine_stepping_db: tuple[float, ...] | None = None
    fine_stopped_db: tuple[float, ...] | None = None
    checks: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        _check(self)

    def step_rate_problem(self, step_hz: float, what: str = "the joint steps") -> str | None:
        """A warning if ``step_hz`` (Hz) is more than ``step_rate_tolerance`` from the tuning's rate.

        A click train's harmonics fall on a joint's narrow modes differently at another rate
        (:class:`TuningFileParams`; docs/audio.md, "Another step rate than the tuning's").
        ``None`` when the rates agree, or when either is unknown (a tuning made before the
        rate was recorded, a rate not heard).
        """
        if self.step_rate_hz is None or not (math.isfinite(step_hz) and step_hz > 0):
            return None
        off = step_hz / self.step_rate_hz - 1.0
        if abs(off) <= TUNING_FILE.step_rate_tolerance + 1e-9:  # 1050 / 1000 - 1 is 0.050000000000000044
            return None
        return (
            f"{what} at {step_hz:.0f} Hz, {100 * off:+.0f} % from the {self.step_rate_hz:.0f} Hz this tuning was "
            f"made at: a stop can be missed or heard late (a count too high); tune at this rate "
            f"(stickslip record, then stickslip tune)"
        )

    # ------------------------------------------------------------- derived
    @property
    def hold_frames(self) -> int:
        """Consecutive above-threshold frames needed to fire (>= 1)."""
        return max(1, int(math.ceil(self.hold_s * self.sample_rate / self.hop - 1e-9)))

    @property
    def latency_s(self) -> float:
        """Typical detected_at - true onset, s (measured when tuned, else estimated)."""
        if self.latency_measured_s is not None:
            return float(self.latency_measured_s)
        return self.onset_lag_s + self.hold_frames * self.hop / self.sample_rate

    @property
    def level_unit(self) -> str:
        """``"dBFS"`` for an absolute band level; ``"dB re a-b Hz"`` for one relative to the reference band."""
        if self.method == "template":
            return "(stop-likeness: 0 stepping, 1 the tuned stop)"
        if self.reference_hz is None:
            return "dBFS"
        return f"dB re {self.reference_hz[0]:.0f}-{self.reference_hz[1]:.0f} Hz"

    def for_sample_rate(self, sample_rate: int) -> Tuning:
        """The same tuning for another sample rate (same durations).

        A template whose upper sub-bands do not fit below 0.45 of the new rate keeps the
        sub-bands that do (the stop is judged on them), provided they hold at least half
        of the stop's signature (in spreads); otherwise, and for a band tuning whose band
        does not fit, :class:`ValueError` says so.
        """
        if sample_rate == self.sample_rate:
            return self
        if (problem := TUNING_FILE.rate_problem(sample_rate)) is not None:
            raise ValueError(problem)
        frame = default_frame(sample_rate) * self.frame // default_frame(self.sample_rate)
        hop = max(1, frame * self.hop // self.frame)
        kw: dict[str, Any] = {"sample_rate": int(sample_rate), "frame": int(frame), "hop": int(hop)}
        if self.method == "template" and self.edges_hz is not None and self.edges_hz[-1] > 0.45 * sample_rate:
            assert self.signature_db is not None and self.spread_db is not None
            nb = sum(1 for e in self.edges_hz[1:] if e <= 0.45 * sample_rate)
            sig, spr = np.asarray(self.signature_db), np.asarray(self.spread_db)
            kept = float(np.sum((sig[:nb] / spr[:nb]) ** 2)) if nb else 0.0
            if nb < 2 or kept < 0.25 * float(np.sum((sig / spr) ** 2)) or not any(abs(v) > 0 for v in sig[:nb]):
                raise ValueError(
                    f"this tuning's stop is heard mostly above {0.45 * sample_rate:.0f} Hz, beyond what a "
                    f"{sample_rate} Hz recording holds; record at {self.sample_rate} Hz or tune at {sample_rate} Hz"
                )
            edges = self.edges_hz[: nb + 1]
            kw.update(
                band_hz=(edges[0], edges[-1]),
                edges_hz=edges,
                signature_db=self.signature_db[:nb],
                spread_db=self.spread_db[:nb],
                stepping_levels_db=None if self.stepping_levels_db is None else self.stepping_levels_db[:nb],
                trim=min(self.trim, nb - 1),
                **{k: None if getattr(self, k) is None else getattr(self, k)[:nb] for k in _CONTINUUM},
            )
        return replace(self, **kw)

    # ------------------------------------------------------------- files
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict; units are in the key names (frame and hop are samples)."""
        return _to_dict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Tuning:
        """Inverse of :meth:`to_dict`; raises :class:`TuningFileError` naming the problem."""
        return _from_dict(d)

    def save(self, path: str | Path) -> Path:
        """Write the tuning as JSON; returns the path."""
        p = Path(path)
        d = self.to_dict()
        # the fine spectra (thousands of levels each) on one line apiece, not one line per level
        long = {k: d[k] for k in ("fine_stepping_db", "fine_stopped_db") if isinstance(d.get(k), list)}
        text = records.dumps_json({**d, **{k: f"@{k}@" for k in long}}, str(p), indent=2)
        for k, v in long.items():
            text = text.replace(f'"@{k}@"', records.dumps_json(v, f"{p}: {k}"))
        records.atomic_write_text(p, text + "\n")
        return p

    @classmethod
    def load(cls, path: str | Path) -> Tuning:
        """Read a tuning written by :meth:`save` (raises TuningFileError / OSError)."""
        p = Path(path)
        text = records.read_tuning_text(p, TuningFileError)
        try:
            d = json.loads(text)
        except json.JSONDecodeError as e:
            raise TuningFileError(f"{p}: not JSON ({e.msg} at line {e.lineno})") from None
        try:
            return cls.from_dict(d)
        except TuningFileError as e:
            raise TuningFileError(f"{p}: {e}") from None

    def report(self) -> str:
        """A few human lines: band (or template), threshold, contrast and margin, latency."""
        return _template_report(self) if self.method == "template" else _report(self)


def _check(t: Tuning) -> None:
    """Refuse a tuning that cannot be used (``ValueError`` naming the field and the reason)."""
    lo, hi = (float(v) for v in t.band_hz)
    object.__setattr__(t, "band_hz", (lo, hi))
    nyq = t.sample_rate / 2
    if (problem := TUNING_FILE.rate_problem(t.sample_rate)) is not None:
        raise ValueError(problem.replace("sample rate", "sample_rate", 1))
    if not 0 <= lo < hi <= nyq:
        raise ValueError(f"band_hz ({lo:g}, {hi:g}) must satisfy 0 <= low < high <= {nyq:g} Hz")
    if not (t.frame >= 32 and t.frame & (t.frame - 1) == 0):
        raise ValueError(f"frame {t.frame} must be a power of two >= 32 samples")
    if not 1 <= t.hop <= t.frame:
        raise ValueError(f"hop {t.hop} must be between 1 and frame ({t.frame}) samples")
    if hi - lo < 2 * t.sample_rate / t.frame:
        raise ValueError(
            f"band_hz ({lo:g}, {hi:g}) is narrower than two frequency bins "
            f"({2 * t.sample_rate / t.frame:g} Hz at frame {t.frame})"
        )
    if t.method not in ("band", "template"):
        raise ValueError(f"method {t.method!r} must be 'band' or 'template'")
    if t.method == "template":
        _check_template(t)
    if t.reference_hz is not None:
        r0, r1 = (float(v) for v in t.reference_hz)
        object.__setattr__(t, "reference_hz", (r0, r1))
        if not (0 <= r0 < r1 <= nyq and r1 - r0 >= 2 * t.sample_rate / t.frame):
            raise ValueError(f"reference_hz ({r0:g}, {r1:g}) must be a band of at least two bins below {nyq:g} Hz")
    if not 0 <= t.max_dips <= 16:
        raise ValueError(f"max_dips {t.max_dips} is outside the allowed 0..16 frames")
    if not math.isfinite(t.threshold_db) or not -200 <= t.threshold_db <= 50:
        raise ValueError(f"threshold_db {t.threshold_db} must be within -200..50 dBFS")
    for name, lo_, hi_ in (
        ("hold_s", 0, 1),
        ("release_s", 0, 10),
        ("hysteresis_db", 0, 60),
        ("onset_lag_s", -1, 1),
    ):
        v = getattr(t, name)
        if not lo_ <= v <= hi_:
            raise ValueError(f"{name} {v} is outside the allowed {lo_}..{hi_}")
    if t.joint is not None and (isinstance(t.joint, bool) or t.joint not in (1, 2, 3)):
        raise ValueError(f"joint {t.joint!r} must be 1, 2 or 3 (or null)")
    for name, lo_, hi_ in (  # what tuning saw: informational, but shown and (latency) used
        ("latency_measured_s", 0, 1),
        ("contrast_db", -400, 400),
        ("margin_db", -400, 400),
        ("stepping_db", -400, 400),
        ("stopped_db", -400, 400),
    ):
        v = getattr(t, name)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not lo_ <= v <= hi_):
            raise ValueError(f"{name} {v!r} must be a number within {lo_}..{hi_} (or null)")


def _check_template(t: Tuning) -> None:
    if t.edges_hz is None or t.signature_db is None or t.spread_db is None:
        raise ValueError("a template tuning needs edges_hz, signature_db and spread_db")
    edges = tuple(float(e) for e in t.edges_hz)
    sig = tuple(float(e) for e in t.signature_db)
    spr = tuple(float(e) for e in t.spread_db)
    object.__setattr__(t, "edges_hz", edges)
    object.__setattr__(t, "signature_db", sig)
    object.__setattr__(t, "spread_db", spr)
    nb = len(edges) - 1
    if nb < 1 or len(sig) != nb or len(spr) != nb:
        raise ValueError(f"edges_hz ({len(edges)}), signature_db ({len(sig)}) and spread_db ({len(spr)}) disagree")
    if any(not b > a for a, b in zip(edges, edges[1:], strict=False)) or edges[-1] > t.sample_rate / 2:
        raise ValueError(f"edges_hz must increase and stay below {t.sample_rate / 2:g} Hz")
    if not all(abs(v) <= 400 for v in sig) or not any(abs(v) > 0 for v in sig):
        raise ValueError("signature_db must be within -400..400 dB and not all zero")
    if not all(1e-3 <= v <= 400 for v in spr):
        raise ValueError("spread_db must be within 0.001..400 dB")
    if t.stepping_levels_db is not None:
        lv = tuple(float(v) for v in t.stepping_levels_db)
        object.__setattr__(t, "stepping_levels_db", lv)
        if len(lv) != nb or not all(abs(v) <= 400 for v in lv):
            raise ValueError(f"stepping_levels_db must hold {nb} levels within -400..400 dBFS")
    if t.drop_threshold is not None:
        dt = tuple(float(v) for v in t.drop_threshold)
        if len(dt) != 2 or not all(math.isfinite(v) and 0.1 <= v <= 100 for v in dt):
            raise ValueError(f"drop_threshold {t.drop_threshold} must be two numbers within 0.1..100 spreads")
        object.__setattr__(t, "drop_threshold", dt)
    _check_continuum(t, nb)
    _check_fine(t)
    if not 0 <= t.trim < nb:
        raise ValueError(f"trim {t.trim} must be 0..{nb - 1} sub-bands")
    for name, lo_, hi_ in (
        ("residual_max", 0.1, 1e3),
        ("decay_ratio", 0, 1),
        ("tau_s", 0.01, 100),
        ("warmup_s", 0, 10),
    ):
        v = getattr(t, name)
        if not lo_ <= v <= hi_:
            raise ValueError(f"{name} {v} is outside the allowed {lo_}..{hi_}")
    if t.per_octave is not None:
        po = t.per_octave
        if isinstance(po, bool) or not isinstance(po, (int, float)) or not 0.5 <= po <= 48:
            raise ValueError(f"per_octave {po!r} must be a number within 0.5..48 sub-bands per octave (or null)")
        object.__setattr__(t, "per_octave", float(po))


def _check_continuum(t: Tuning, nb: int) -> None:
    if t.step_rate_hz is not None:
        r = float(t.step_rate_hz)
        if not (math.isfinite(r) and 10.0 <= r <= t.sample_rate / 4):
            raise ValueError(f"step_rate_hz {t.step_rate_hz} must be within 10..{t.sample_rate / 4:g} Hz")
        object.__setattr__(t, "step_rate_hz", r)
    given = [getattr(t, k) is not None for k in _CONTINUUM]
    if any(given) and not (all(given) and t.step_rate_hz is not None):
        raise ValueError(
            "continuum_levels_db, continuum_signature_db and continuum_spread_db come together, with step_rate_hz"
        )
    if not all(given):
        return
    for k in _CONTINUUM:
        v = tuple(math.nan if e is None else float(e) for e in getattr(t, k))
        object.__setattr__(t, k, v)
        if len(v) != nb or any(not abs(e) <= 400 for e in v if not math.isnan(e)):
            raise ValueError(f"{k} must hold {nb} numbers within -400..400 dB (null where a sub-band has no continuum)")
    if any(not 1e-3 <= v for v in t.continuum_spread_db or () if not math.isnan(v)):
        raise ValueError("continuum_spread_db must be at least 0.001 dB")


def _check_fine(t: Tuning) -> None:
    given = [getattr(t, k) is not None for k in _FINE]
    if any(given) and not all(given):  # without step_rate_hz they are kept, and not used
        raise ValueError(f"{', '.join(_FINE)} come together")
    if not all(given):
        return
    start, bin_hz = float(t.fine_start_hz or 0.0), float(t.fine_bin_hz or 0.0)
    if not (math.isfinite(start) and 0.0 <= start < t.sample_rate / 2):
        raise ValueError(f"fine_start_hz {t.fine_start_hz} must be within 0..{t.sample_rate / 2:g} Hz")
    if not (math.isfinite(bin_hz) and 0.1 <= bin_hz <= 100.0):
        raise ValueError(f"fine_bin_hz {t.fine_bin_hz} must be within 0.1..100 Hz")
    object.__setattr__(t, "fine_start_hz", start)
    object.__setattr__(t, "fine_bin_hz", bin_hz)
    n = None
    for k in ("fine_stepping_db", "fine_stopped_db"):
        v = tuple(float(e) for e in getattr(t, k))
        object.__setattr__(t, k, v)
        top = TUNING_FILE.fine_max
        if not 2 <= len(v) <= top or not all(abs(e) <= 400 for e in v):
            raise ValueError(f"{k} must hold 2..{top} levels within -400..400 dB")
        if n is not None and len(v) != n:
            raise ValueError("fine_stepping_db and fine_stopped_db must hold as many levels")
        n = len(v)


def _to_dict(t: Tuning) -> dict[str, Any]:
    """JSON-ready dict; units are in the key names (frame and hop are samples)."""
    d = asdict(t)
    d.pop("extra")
    d["band_hz"] = list(t.band_hz)
    d["reference_hz"] = list(t.reference_hz) if t.reference_hz is not None else None
    d["latency_s"] = t.latency_s
    version = 1
    if t.method == "template":
        version = 2
        for k in ("edges_hz", "signature_db", "spread_db", "stepping_levels_db", "drop_threshold"):
            d[k] = list(d[k]) if d[k] is not None else None
        for k in _CONTINUUM:
            d[k] = None if d[k] is None else [None if math.isnan(v) else v for v in d[k]]
        for k in ("fine_stepping_db", "fine_stopped_db"):
            d[k] = None if d[k] is None else list(d[k])
        # absent, as in files made before they were recorded
        for k in ("step_rate_hz", "per_octave", *_CONTINUUM, *_FINE):
            if d[k] is None:
                d.pop(k)
    else:
        for k in (
            "method",
            "edges_hz",
            "signature_db",
            "spread_db",
            "residual_max",
            "decay_ratio",
            "tau_s",
            "warmup_s",
            "trim",
            "checks",
            "stepping_levels_db",
            "drop_threshold",
            "step_rate_hz",
            "per_octave",
            *_CONTINUUM,
            *_FINE,
        ):
            d.pop(k)
    return {"kind": _KIND, "version": version, **d, **({"extra": t.extra} if t.extra else {})}


_LISTS = ("edges_hz", "signature_db", "spread_db", "stepping_levels_db", "drop_threshold", "fine_stepping_db",
          "fine_stopped_db")  # fmt: skip
_NUMBERS = ("threshold_db", "hold_s", "hysteresis_db", "release_s", "onset_lag_s", "residual_max", "decay_ratio",
            "tau_s", "warmup_s")  # fmt: skip
_RATES = ("step_rate_hz", "per_octave", "fine_start_hz", "fine_bin_hz")
_SEEN = ("latency_measured_s", "contrast_db", "margin_db", "stepping_db", "stopped_db")


def _from_dict(d: dict[str, Any]) -> Tuning:
    """Inverse of :meth:`Tuning.to_dict`; raises :class:`TuningFileError` naming the problem."""
    if not isinstance(d, dict):
        raise TuningFileError("a tuning must be a JSON object")
    if d.get("kind", _KIND) != _KIND:
        raise TuningFileError(f"not a stop-detector tuning (kind {d.get('kind')!r})")
    version = d.get("version", 1)
    if isinstance(version, bool) or version not in (1, 2):
        newer = isinstance(version, int) and not isinstance(version, bool) and version > 2
        raise TuningFileError(
            f"tuning version {version!r} is newer than this stickslip understands (1 or 2); "
            "upgrade stickslip or re-tune with 'stickslip tune'"
            if newer
            else f"tuning version {version!r} is not a version stickslip writes (the whole numbers 1 or 2): "
            "re-tune with 'stickslip tune'"
        )
    for key in ("band_hz", "threshold_db"):
        if key not in d:
            raise TuningFileError(f"tuning lacks {key!r}")
    known = {f for f in Tuning.__dataclass_fields__}
    kwargs = {k: v for k, v in d.items() if k in known}
    try:
        _parse_bands(kwargs)
        _parse_lists(kwargs)
        _parse_optional(kwargs, _RATES)
        _parse_checks(kwargs)
        _parse_numbers(kwargs)
        return Tuning(**kwargs)
    except TuningFileError:
        raise
    except (TypeError, ValueError) as e:
        raise TuningFileError(f"bad tuning: {e}") from None


def _parse_bands(kwargs: dict[str, Any]) -> None:
    """``band_hz`` and ``reference_hz`` as pairs of numbers, Hz."""
    band = kwargs["band_hz"]
    if not (isinstance(band, (list, tuple)) and len(band) == 2):
        raise TuningFileError("band_hz must be [low_Hz, high_Hz]")
    kwargs["band_hz"] = (_number("band_hz[0]", band[0]), _number("band_hz[1]", band[1]))
    ref = kwargs.get("reference_hz")
    if ref is not None:
        if not (isinstance(ref, (list, tuple)) and len(ref) == 2):
            raise TuningFileError("reference_hz must be [low_Hz, high_Hz] or null")
        kwargs["reference_hz"] = (_number("reference_hz[0]", ref[0]), _number("reference_hz[1]", ref[1]))


def _parse_lists(kwargs: dict[str, Any]) -> None:
    """The lists of numbers (the continuum's may hold nulls: NaN) as tuples."""
    for k in _LISTS:
        if kwargs.get(k) is not None:
            if not isinstance(kwargs[k], (list, tuple)):
                raise TuningFileError(f"{k} must be a list of numbers")
            kwargs[k] = tuple(_number(f"{k}[{i}]", v) for i, v in enumerate(kwargs[k]))
    for k in _CONTINUUM:
        if kwargs.get(k) is not None:
            if not isinstance(kwargs[k], (list, tuple)):
                raise TuningFileError(f"{k} must be a list of numbers or nulls")
            kwargs[k] = tuple(math.nan if v is None else _number(f"{k}[{i}]", v) for i, v in enumerate(kwargs[k]))


def _parse_optional(kwargs: dict[str, Any], keys: tuple[str, ...]) -> None:
    """The numbers ``keys`` that may be null."""
    for k in keys:
        if kwargs.get(k) is not None:
            kwargs[k] = _number(k, kwargs[k])


_CHECK_NUMBERS = ("false_alarms_per_hour", "false_alarms", "checked_s", "stops_found", "stops", "latency_median_s")
"""The self-check's numbers that :meth:`Tuning.report` and ``tune`` read (each finite and >= 0 when given)."""


def _parse_checks(kwargs: dict[str, Any]) -> None:
    """The self-check record: an object whose numbers are numbers and whose warnings are text (the rest is kept)."""
    checks = kwargs.get("checks")
    if checks is None:
        return
    if not isinstance(checks, dict):
        raise TuningFileError("checks must be an object or null")
    for k in _CHECK_NUMBERS:
        if k in checks and not (_number(f"checks.{k}", checks[k]) >= 0):
            raise TuningFileError(f"checks.{k} must be a number >= 0, got {checks[k]!r}")
    warnings = checks.get("warnings", [])
    if not (isinstance(warnings, list) and all(isinstance(w, str) for w in warnings)):
        raise TuningFileError("checks.warnings must be a list of texts")


def _parse_numbers(kwargs: dict[str, Any]) -> None:
    """The numbers (finite), what tuning saw (or null) and the integers (whole)."""
    for k in _NUMBERS:
        if k in kwargs:
            kwargs[k] = _number(k, kwargs[k])
    _parse_optional(kwargs, _SEEN)
    for k in ("sample_rate", "frame", "hop", "max_dips", "trim", "joint"):
        if k == "joint" and kwargs.get(k) is None:
            continue
        if k in kwargs:
            v = kwargs[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v != int(v):
                raise TuningFileError(f"{k} must be an integer, got {v!r}")
            kwargs[k] = int(v)


def _saw_levels(t: Tuning) -> bool:
    """Whether ``t`` holds all four levels tuning saw (a hand-edited file may hold some, each optional)."""
    return None not in (t.contrast_db, t.margin_db, t.stepping_db, t.stopped_db)


def _report(t: Tuning) -> str:
    """A band tuning's report: band, threshold, contrast and margin."""
    lines = [
        f"band {t.band_hz[0]:.0f}-{t.band_hz[1]:.0f} Hz, threshold {t.threshold_db:.1f} {t.level_unit}",
        f"frame {t.frame} samples ({1e3 * t.frame / t.sample_rate:.1f} ms), "
        f"hop {t.hop} ({1e3 * t.hop / t.sample_rate:.2f} ms), "
        f"hold {1e3 * t.hold_s:.1f} ms, hysteresis {t.hysteresis_db:.1f} dB",
    ]
    if _saw_levels(t):
        lines.append(
            f"stepping <= {t.stepping_db:.1f} {t.level_unit}, stopped >= {t.stopped_db:.1f} "
            f"{t.level_unit}: "
            f"contrast {t.contrast_db:.1f} dB, margin {t.margin_db:.1f} dB"
        )
    lines.append(f"latency {1e3 * t.latency_s:.1f} ms")
    return "\n".join(lines)


def _template_report(t: Tuning) -> str:
    assert t.edges_hz is not None and t.signature_db is not None
    sig = np.asarray(t.signature_db)
    k = int(np.argmax(np.abs(sig)))
    e = t.edges_hz
    per = f" ({t.per_octave:g} per octave)" if t.per_octave is not None else ""
    lines = [
        f"spectral template over {e[0]:.0f}-{e[-1]:.0f} Hz in {len(e) - 1} sub-bands{per}; the stop departs most "
        f"at {e[k]:.0f}-{e[k + 1]:.0f} Hz ({sig[k]:+.1f} dB)",
        f"stop signature {', '.join(f'{v:+.0f}' for v in sig)} dB",
        f"fires at stop-likeness {t.threshold_db:.2f} (stepping 0, the stop 1) held "
        f"{1e3 * t.hold_s:.1f} ms, residual <= {t.residual_max:.1f}; frame "
        f"{t.frame} samples ({1e3 * t.frame / t.sample_rate:.1f} ms), hop {t.hop}",
    ]
    if _saw_levels(t):
        lines.append(
            f"worst stepping frame {t.stepping_db:.2f}, stop's low {t.stopped_db:.2f}: "
            f"margin {t.margin_db:.2f} (stop-likeness), stop departure {t.contrast_db:.1f} dB"
        )
    lines.append(f"latency {1e3 * t.latency_s:.1f} ms, onset lag {1e3 * t.onset_lag_s:.1f} ms")
    c = t.checks or {}
    if all(k in c for k in _CHECK_NUMBERS):  # (a record with one of them left out is not reported in part)
        lines.append(
            f"self-check with knocks, babble, +-20 dB gain and a second click train: "
            f"{c['false_alarms_per_hour']:.0f} false alarms per hour expected "
            f"({c['false_alarms']} in {c['checked_s']:.0f} s), stop found in {c['stops_found']}/{c['stops']} "
            f"cases, latency median {1e3 * c['latency_median_s']:.1f} ms"
        )
    return "\n".join(lines)
