"""Streaming end-stop detector: band power per frame, threshold, hysteresis, hold.

Per frame of ``frame`` samples (every ``hop`` samples) the detector takes a
Hann-windowed rfft and the power in the joint's band ``band_hz``, in dB relative to
full scale (``10 log10`` of the mean square the band contributes, so white noise of
variance s^2 spread over the whole spectrum sums to ``10 log10 s^2`` over all bands).

A stop is declared when the band level stays at or above ``threshold_db`` for
``hold_s`` (a knock or a burst of speech is shorter; up to ``max_dips`` frames of the
hold may dip below); it then stays latched until the
level has been below ``threshold_db - hysteresis_db`` for ``release_s``, so one stop
gives one event. There is no look-ahead beyond one frame.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import records
from ..plotting import has_display
from .template import CHUNK, TemplateParams, TemplateState, levels_from_frames

__all__ = [
    "StopDetector",
    "StopEvent",
    "Tuning",
    "TuningFileError",
    "band_levels_db",
    "detect",
    "frame_levels_db",
    "plot_levels",
]

_FLOOR = 1e-20
_LIMIT = 1e15  # samples beyond this (full scale is 1) are clipped: their squares stay finite in float32
_KIND = "stickslip.audio.Tuning"


class TuningFileError(ValueError):
    """A tuning file or dictionary that cannot be used (names the key and the reason)."""


def default_frame(sample_rate: int) -> int:
    """Frame length in samples: the power of two closest to 10.7 ms (512 at 48 kHz)."""
    return int(2 ** round(math.log2(sample_rate * 512 / 48_000)))


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
        ``"template"``: the spectral-template change detector (:mod:`.template`; what
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
        detector tell that it began listening at the stop (see :mod:`.template`).
    drop_threshold : (float, float) or None
        ``"template"``: the broad and the local drop below the stepping template at which
        a frame counts as a stop whatever its signature (spreads, see
        :class:`~stickslip.audio.template.DropMeter`); None: only the tuned signature counts.
    checks : dict or None
        What :func:`~stickslip.audio.tuning.tune` verified (false alarms per hour with
        interference injected, latency); informational.

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
    checks: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        lo, hi = (float(v) for v in self.band_hz)
        object.__setattr__(self, "band_hz", (lo, hi))
        nyq = self.sample_rate / 2
        if not 8_000 <= self.sample_rate <= 192_000:
            raise ValueError(f"sample_rate {self.sample_rate} Hz is outside 8000-192000 Hz")
        if not 0 <= lo < hi <= nyq:
            raise ValueError(f"band_hz ({lo:g}, {hi:g}) must satisfy 0 <= low < high <= {nyq:g} Hz")
        if not (self.frame >= 32 and self.frame & (self.frame - 1) == 0):
            raise ValueError(f"frame {self.frame} must be a power of two >= 32 samples")
        if not 1 <= self.hop <= self.frame:
            raise ValueError(f"hop {self.hop} must be between 1 and frame ({self.frame}) samples")
        if hi - lo < 2 * self.sample_rate / self.frame:
            raise ValueError(
                f"band_hz ({lo:g}, {hi:g}) is narrower than two frequency bins "
                f"({2 * self.sample_rate / self.frame:g} Hz at frame {self.frame})"
            )
        if self.method not in ("band", "template"):
            raise ValueError(f"method {self.method!r} must be 'band' or 'template'")
        if self.method == "template":
            self._check_template()
        if self.reference_hz is not None:
            r0, r1 = (float(v) for v in self.reference_hz)
            object.__setattr__(self, "reference_hz", (r0, r1))
            if not (0 <= r0 < r1 <= nyq and r1 - r0 >= 2 * self.sample_rate / self.frame):
                raise ValueError(f"reference_hz ({r0:g}, {r1:g}) must be a band of at least two bins below {nyq:g} Hz")
        if not 0 <= self.max_dips <= 16:
            raise ValueError(f"max_dips {self.max_dips} is outside the allowed 0..16 frames")
        if not math.isfinite(self.threshold_db) or not -200 <= self.threshold_db <= 50:
            raise ValueError(f"threshold_db {self.threshold_db} must be within -200..50 dBFS")
        for name, lo_, hi_ in (
            ("hold_s", 0, 1),
            ("release_s", 0, 10),
            ("hysteresis_db", 0, 60),
            ("onset_lag_s", -1, 1),
        ):
            v = getattr(self, name)
            if not lo_ <= v <= hi_:
                raise ValueError(f"{name} {v} is outside the allowed {lo_}..{hi_}")

    def _check_template(self) -> None:
        if self.edges_hz is None or self.signature_db is None or self.spread_db is None:
            raise ValueError("a template tuning needs edges_hz, signature_db and spread_db")
        edges = tuple(float(e) for e in self.edges_hz)
        sig = tuple(float(e) for e in self.signature_db)
        spr = tuple(float(e) for e in self.spread_db)
        object.__setattr__(self, "edges_hz", edges)
        object.__setattr__(self, "signature_db", sig)
        object.__setattr__(self, "spread_db", spr)
        nb = len(edges) - 1
        if nb < 1 or len(sig) != nb or len(spr) != nb:
            raise ValueError(f"edges_hz ({len(edges)}), signature_db ({len(sig)}) and spread_db ({len(spr)}) disagree")
        if any(not b > a for a, b in zip(edges, edges[1:], strict=False)) or edges[-1] > self.sample_rate / 2:
            raise ValueError(f"edges_hz must increase and stay below {self.sample_rate / 2:g} Hz")
        if not all(math.isfinite(v) for v in sig) or not any(abs(v) > 0 for v in sig):
            raise ValueError("signature_db must be finite and not all zero")
        if not all(math.isfinite(v) and v > 0 for v in spr):
            raise ValueError("spread_db must be finite and positive")
        if self.stepping_levels_db is not None:
            lv = tuple(float(v) for v in self.stepping_levels_db)
            object.__setattr__(self, "stepping_levels_db", lv)
            if len(lv) != nb or not all(math.isfinite(v) for v in lv):
                raise ValueError(f"stepping_levels_db must hold {nb} finite levels")
        if self.drop_threshold is not None:
            dt = tuple(float(v) for v in self.drop_threshold)
            if len(dt) != 2 or not all(math.isfinite(v) and 0.1 <= v <= 100 for v in dt):
                raise ValueError(f"drop_threshold {self.drop_threshold} must be two numbers within 0.1..100 spreads")
            object.__setattr__(self, "drop_threshold", dt)
        if not 0 <= self.trim < nb:
            raise ValueError(f"trim {self.trim} must be 0..{nb - 1} sub-bands")
        for name, lo_, hi_ in (
            ("residual_max", 0.1, 1e3),
            ("decay_ratio", 0, 1),
            ("tau_s", 0.01, 100),
            ("warmup_s", 0, 10),
        ):
            v = getattr(self, name)
            if not lo_ <= v <= hi_:
                raise ValueError(f"{name} {v} is outside the allowed {lo_}..{hi_}")

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
            )
        return replace(self, **kw)

    # ------------------------------------------------------------- files
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict; units are in the key names (frame and hop are samples)."""
        d = asdict(self)
        d.pop("extra")
        d["band_hz"] = list(self.band_hz)
        d["reference_hz"] = list(self.reference_hz) if self.reference_hz is not None else None
        d["latency_s"] = self.latency_s
        version = 1
        if self.method == "template":
            version = 2
            for k in ("edges_hz", "signature_db", "spread_db", "stepping_levels_db", "drop_threshold"):
                d[k] = list(d[k]) if d[k] is not None else None
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
            ):
                d.pop(k)
        return {"kind": _KIND, "version": version, **d, **({"extra": self.extra} if self.extra else {})}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Tuning:
        """Inverse of :meth:`to_dict`; raises :class:`TuningFileError` naming the problem."""
        if not isinstance(d, dict):
            raise TuningFileError("a tuning must be a JSON object")
        if d.get("kind", _KIND) != _KIND:
            raise TuningFileError(f"not a stop-detector tuning (kind {d.get('kind')!r})")
        version = d.get("version", 1)
        if version not in (1, 2):
            raise TuningFileError(
                f"tuning version {version!r} is newer than this stickslip understands (1 or 2); "
                "upgrade stickslip or re-tune with 'stickslip tune'"
            )
        for key in ("band_hz", "threshold_db"):
            if key not in d:
                raise TuningFileError(f"tuning lacks {key!r}")
        known = {f for f in cls.__dataclass_fields__}
        kwargs = {k: v for k, v in d.items() if k in known}
        try:
            band = kwargs["band_hz"]
            if not (isinstance(band, (list, tuple)) and len(band) == 2):
                raise TuningFileError("band_hz must be [low_Hz, high_Hz]")
            kwargs["band_hz"] = (float(band[0]), float(band[1]))
            ref = kwargs.get("reference_hz")
            if ref is not None:
                if not (isinstance(ref, (list, tuple)) and len(ref) == 2):
                    raise TuningFileError("reference_hz must be [low_Hz, high_Hz] or null")
                kwargs["reference_hz"] = (float(ref[0]), float(ref[1]))
            for k in ("edges_hz", "signature_db", "spread_db", "stepping_levels_db", "drop_threshold"):
                if kwargs.get(k) is not None:
                    if not isinstance(kwargs[k], (list, tuple)):
                        raise TuningFileError(f"{k} must be a list of numbers")
                    kwargs[k] = tuple(float(v) for v in kwargs[k])
            if kwargs.get("checks") is not None and not isinstance(kwargs["checks"], dict):
                raise TuningFileError("checks must be an object or null")
            for k in (
                "threshold_db",
                "hold_s",
                "hysteresis_db",
                "release_s",
                "onset_lag_s",
                "residual_max",
                "decay_ratio",
                "tau_s",
                "warmup_s",
            ):
                if k in kwargs:
                    kwargs[k] = float(kwargs[k])
            for k in ("sample_rate", "frame", "hop", "max_dips", "trim"):
                if k in kwargs:
                    v = kwargs[k]
                    if isinstance(v, bool) or not isinstance(v, (int, float)) or v != int(v):
                        raise TuningFileError(f"{k} must be an integer, got {v!r}")
                    kwargs[k] = int(v)
            return cls(**kwargs)
        except TuningFileError:
            raise
        except (TypeError, ValueError) as e:
            raise TuningFileError(f"bad tuning: {e}") from None

    def save(self, path: str | Path) -> Path:
        """Write the tuning as JSON; returns the path."""
        p = Path(path)
        records.atomic_write_text(p, json.dumps(self.to_dict(), indent=2) + "\n")
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
        """A few human lines: band, threshold, contrast and margin."""
        if self.method == "template":
            return self._template_report()
        lines = [
            f"band {self.band_hz[0]:.0f}-{self.band_hz[1]:.0f} Hz, threshold {self.threshold_db:.1f} {self.level_unit}",
            f"frame {self.frame} samples ({1e3 * self.frame / self.sample_rate:.1f} ms), "
            f"hop {self.hop} ({1e3 * self.hop / self.sample_rate:.2f} ms), "
            f"hold {1e3 * self.hold_s:.1f} ms, hysteresis {self.hysteresis_db:.1f} dB",
        ]
        if self.contrast_db is not None:
            lines.append(
                f"stepping <= {self.stepping_db:.1f} {self.level_unit}, stopped >= {self.stopped_db:.1f} "
                f"{self.level_unit}: "
                f"contrast {self.contrast_db:.1f} dB, margin {self.margin_db:.1f} dB"
            )
        lines.append(f"latency {1e3 * self.latency_s:.1f} ms")
        return "\n".join(lines)

    def _template_report(self) -> str:
        assert self.edges_hz is not None and self.signature_db is not None
        sig = np.asarray(self.signature_db)
        k = int(np.argmax(np.abs(sig)))
        e = self.edges_hz
        lines = [
            f"spectral template over {e[0]:.0f}-{e[-1]:.0f} Hz in {len(e) - 1} sub-bands; the stop departs most "
            f"at {e[k]:.0f}-{e[k + 1]:.0f} Hz ({sig[k]:+.1f} dB)",
            f"stop signature {', '.join(f'{v:+.0f}' for v in sig)} dB",
            f"fires at stop-likeness {self.threshold_db:.2f} (stepping 0, the stop 1) held "
            f"{1e3 * self.hold_s:.1f} ms, residual <= {self.residual_max:.1f}; frame "
            f"{self.frame} samples ({1e3 * self.frame / self.sample_rate:.1f} ms), hop {self.hop}",
        ]
        if self.contrast_db is not None:
            lines.append(
                f"worst stepping frame {self.stepping_db:.2f}, stop's low {self.stopped_db:.2f}: "
                f"margin {self.margin_db:.2f} (stop-likeness), stop departure {self.contrast_db:.1f} dB"
            )
        lines.append(f"latency {1e3 * self.latency_s:.1f} ms, onset lag {1e3 * self.onset_lag_s:.1f} ms")
        c = self.checks or {}
        if "false_alarms_per_hour" in c:
            lines.append(
                f"self-check with knocks, babble, +-20 dB gain and a second click train: "
                f"{c['false_alarms_per_hour']:.0f} false alarms per hour expected "
                f"({c['false_alarms']} in {c['checked_s']:.0f} s), stop found in {c['stops_found']}/{c['stops']} "
                f"cases, latency median {1e3 * c['latency_median_s']:.1f} ms"
            )
        return "\n".join(lines)

    def template_params(self) -> TemplateParams:
        """The template detector's parameters (``method == "template"`` only)."""
        assert self.edges_hz is not None and self.signature_db is not None and self.spread_db is not None
        return TemplateParams(
            sample_rate=self.sample_rate,
            frame=self.frame,
            hop=self.hop,
            edges_hz=self.edges_hz,
            signature_db=self.signature_db,
            spread_db=self.spread_db,
            threshold=self.threshold_db,
            residual_max=self.residual_max,
            hold_frames=self.hold_frames,
            max_dips=self.max_dips,
            release_frames=max(1, int(math.ceil(self.release_s * self.sample_rate / self.hop))),
            hysteresis=self.hysteresis_db,
            decay_ratio=self.decay_ratio,
            tau_s=self.tau_s,
            warmup_chunks=max(1, int(math.ceil(self.warmup_s * self.sample_rate / self.hop / CHUNK - 1e-9))),
            trim=self.trim,
            onset_lag_s=self.onset_lag_s,
            stepping_levels_db=self.stepping_levels_db,
            drop_threshold=self.drop_threshold,
        )


@dataclass(frozen=True)
class StopEvent:
    """One end stop heard.

    Attributes
    ----------
    detected_at_s : float
        Stream time of the last sample consumed when the event fired, s: the last
        sample of the frame that completed the hold. It does not depend on how the
        stream was cut into blocks (later samples of the same block were not needed).
    onset_s : float
        Estimated time the stop actually began, s.
    level_db : float
        Band level of the frame that fired, dBFS.
    """

    detected_at_s: float
    onset_s: float
    level_db: float

    def to_dict(self) -> dict[str, float]:
        return {
            "detected_at_s": self.detected_at_s,
            "onset_s": self.onset_s,
            "level_db": self.level_db,
        }


def _band_bins(tuning_or_band: tuple[float, float], sample_rate: int, frame: int) -> tuple[int, int]:
    lo, hi = tuning_or_band
    freqs = np.fft.rfftfreq(frame, 1 / sample_rate)
    i0 = int(np.searchsorted(freqs, lo, side="left"))
    i1 = int(np.searchsorted(freqs, hi, side="right"))
    return i0, max(i1, i0 + 1)


def _window(frame: int) -> tuple[np.ndarray, float]:
    w = np.hanning(frame + 1)[:-1]  # periodic Hann
    scale = 2.0 / (frame * float(np.sum(w**2)))
    return w, scale


def frame_power_spectra(samples: np.ndarray, frame: int, hop: int) -> np.ndarray:
    """Per-frame one-sided power spectra (frames x bins), scaled so bins sum to mean square.

    Frame ``i`` covers samples ``[i*hop, i*hop + frame)``.
    """
    x = np.asarray(samples, dtype=np.float64)
    if x.size < frame:
        return np.zeros((0, frame // 2 + 1))
    frames = np.lib.stride_tricks.sliding_window_view(x, frame)[::hop]
    w, scale = _window(frame)
    spec = np.fft.rfft(frames * w, axis=1)
    p = (spec.real**2 + spec.imag**2) * scale
    p[:, 0] *= 0.5
    if frame % 2 == 0:
        p[:, -1] *= 0.5
    return p


def frame_levels_db(samples: np.ndarray, tuning: Tuning) -> np.ndarray:
    """The detector's level for every frame of ``samples`` (frame i ends at sample i*hop+frame-1).

    dBFS, or dB relative to the reference band when the tuning has one; for a template
    tuning the stop-likeness (dimensionless, NaN while the template is learned).
    """
    if tuning.method == "template":
        det = StopDetector(tuning)
        assert det._template is not None
        det._template.trace = []
        det.feed(np.asarray(samples))
        return np.asarray(det._template.trace, dtype=np.float64)
    return band_levels_db(samples, tuning.sample_rate, tuning.frame, tuning.hop, tuning.band_hz, tuning.reference_hz)


def band_levels_db(
    samples: NDArray[Any],
    sample_rate: int,
    frame: int,
    hop: int,
    band_hz: tuple[float, float],
    reference_hz: tuple[float, float] | None = None,
) -> NDArray[np.float64]:
    """Band level per frame, dBFS (see :func:`frame_power_spectra`); minus the reference band's if given."""
    p = frame_power_spectra(samples, frame, hop)
    i0, i1 = _band_bins(band_hz, sample_rate, frame)
    level = 10 * np.log10(p[:, i0:i1].sum(axis=1) + _FLOOR)
    if reference_hz is not None:
        r0, r1 = _band_bins(reference_hz, sample_rate, frame)
        level -= 10 * np.log10(p[:, r0:r1].sum(axis=1) + _FLOOR)
    return np.asarray(level, dtype=np.float64)


class StopDetector:
    """Streaming end-stop detector: ``feed`` blocks of samples, get :class:`StopEvent` s.

    Parameters
    ----------
    tuning : Tuning
        Band, threshold and timing (its ``sample_rate`` must be the stream's).
    t0_s : float
        Stream time of the first sample fed, s.

    Examples
    --------
    >>> det = StopDetector(Tuning(band_hz=(5600, 7100), threshold_db=-50))
    >>> det.feed(np.zeros(4800, dtype=np.float32))
    []
    """

    def __init__(self, tuning: Tuning, t0_s: float = 0.0) -> None:
        self.tuning = tuning
        self._template: TemplateState | None = None
        if tuning.method == "template":
            assert tuning.edges_hz is not None
            self._template = TemplateState(tuning.template_params(), t0_s)
            freqs = np.fft.rfftfreq(tuning.frame, 1 / tuning.sample_rate)
            self._edge_bins = np.asarray(
                np.searchsorted(freqs, np.asarray(tuning.edges_hz), side="left"), dtype=np.intp
            )
        self._w, self._scale = _window(tuning.frame)
        self._i0, self._i1 = _band_bins(tuning.band_hz, tuning.sample_rate, tuning.frame)
        self._ref = _band_bins(tuning.reference_hz, tuning.sample_rate, tuning.frame) if tuning.reference_hz else None
        self._hold = tuning.hold_frames
        self._full = (1 << (self._hold + tuning.max_dips)) - 1
        self._release = max(1, int(math.ceil(tuning.release_s * tuning.sample_rate / tuning.hop)))
        self.reset(t0_s)

    def reset(self, t0_s: float = 0.0) -> None:
        """Forget everything; the next sample fed is at stream time ``t0_s``."""
        self._t0 = float(t0_s)
        self._buf = np.zeros(0, dtype=np.float64)
        self._buf_start = 0  # absolute sample index of _buf[0]
        self._next = 0  # absolute sample index where the next frame starts
        self._mask = 0  # bit i: frame i hops ago was above threshold
        self._latched = False
        self._below = 0
        self._prev_db = -np.inf
        self._cross_t = math.nan
        self.levels_seen = 0
        if self._template is not None:
            self._template.reset(t0_s)

    @property
    def latency_s(self) -> float:
        """Typical detected_at - true onset, s (for a traverse's latency correction)."""
        return self.tuning.latency_s

    @property
    def latched(self) -> bool:
        """True while a stop is being heard (after it fired, until released)."""
        if self._template is not None:
            return self._template.latched
        return self._latched

    @property
    def level(self) -> float:
        """The latest frame's level in the tuning's unit (stop-likeness for a template tuning)."""
        if self._template is not None:
            return self._template.last_a
        return float(self._prev_db)

    @property
    def ready(self) -> bool:
        """False while a template detector is still learning the stepping sound (it cannot fire yet)."""
        return self._template is None or not self._template.warming

    def feed(self, block: np.ndarray) -> list[StopEvent]:
        """Consume a block of mono samples; return the stops that fired in it."""
        x = np.asarray(block, dtype=np.float64)
        if x.ndim != 1:
            raise ValueError(f"feed expects a 1-D mono block, got shape {x.shape}")
        if x.size and not float(np.max(np.abs(x))) <= _LIMIT:  # NaN, infinity or absurd values: bounded
            x = np.clip(np.nan_to_num(x, nan=0.0, posinf=_LIMIT, neginf=-_LIMIT), -_LIMIT, _LIMIT)
        tu = self.tuning
        F, H = tu.frame, tu.hop
        self._buf = np.concatenate((self._buf, x)) if self._buf.size else x.copy()
        avail_end = self._buf_start + self._buf.size
        n_frames = (avail_end - F - self._next) // H + 1 if avail_end - self._next >= F else 0
        events: list[StopEvent] = []
        if n_frames > 0:
            off = self._next - self._buf_start
            seg = self._buf[off:]
            view = np.lib.stride_tricks.as_strided(
                seg,
                shape=(n_frames, F),
                strides=(H * seg.strides[0], seg.strides[0]),
                writeable=False,
            )
            if self._template is not None:
                v = levels_from_frames(view, self._w, self._scale, self._edge_bins)
                ends = self._next + np.arange(n_frames, dtype=np.int64) * H + F - 1
                for dec in self._template.process(v, ends):
                    events.append(
                        StopEvent(
                            detected_at_s=self._t0 + dec.end_sample / tu.sample_rate,
                            onset_s=dec.cross_t_s - tu.onset_lag_s,
                            level_db=dec.a,
                        )
                    )
                levels = None
            elif self._ref is None:
                spec = np.fft.rfft(view * self._w, axis=1)[:, self._i0 : self._i1]
                power = (spec.real**2 + spec.imag**2).sum(axis=1) * self._scale
                levels = 10 * np.log10(power + _FLOOR)
            else:  # the band relative to the reference band: a microphone gain change cancels
                spec = np.fft.rfft(view * self._w, axis=1)
                p = spec.real**2 + spec.imag**2
                r0, r1 = self._ref
                levels = 10 * np.log10(p[:, self._i0 : self._i1].sum(axis=1) * self._scale + _FLOOR) - 10 * np.log10(
                    p[:, r0:r1].sum(axis=1) * self._scale + _FLOOR
                )
            if levels is not None:
                ends = self._next + np.arange(n_frames) * H + F - 1
                events = self._run(levels, ends)
            self._next += n_frames * H
            self.levels_seen += n_frames
        drop = self._next - self._buf_start
        if drop > 0:
            self._buf = self._buf[drop:]
            self._buf_start += drop
        return events

    def _run(self, levels: np.ndarray, ends: np.ndarray) -> list[StopEvent]:
        tu = self.tuning
        thr, rel = tu.threshold_db, tu.threshold_db - tu.hysteresis_db
        sr, H = tu.sample_rate, tu.hop
        if not self._latched and self._mask == 0 and float(levels.max()) < thr:
            self._prev_db = float(levels[-1])  # fast path: nothing near a stop
            return []
        events = []
        prev = self._prev_db
        full = self._full
        for lev, end in zip(levels.tolist(), ends.tolist(), strict=True):
            if self._latched:
                if lev < rel:
                    self._below += 1
                    if self._below >= self._release:
                        self._latched = False
                        self._mask = 0
                else:
                    self._below = 0
            else:
                above = lev >= thr
                if above and self._mask == 0:
                    # interpolate the crossing between the previous frame and this one
                    t_end = self._t0 + end / sr
                    if math.isfinite(prev) and prev < thr and lev > prev:
                        frac = (thr - prev) / (lev - prev)
                        self._cross_t = float(t_end - (1 - frac) * H / sr)
                    else:
                        self._cross_t = t_end
                # debounce: hold_frames above threshold among the last
                # hold_frames + max_dips frames (a knock lights fewer; a stop all)
                self._mask = ((self._mask << 1) | above) & full
                if above and self._mask.bit_count() >= self._hold:
                    self._latched = True
                    self._below = 0
                    events.append(
                        StopEvent(
                            detected_at_s=self._t0 + end / sr,
                            onset_s=self._cross_t - tu.onset_lag_s,
                            level_db=float(lev),
                        )
                    )
            prev = lev
        self._prev_db = prev
        return events


def detect(
    samples: np.ndarray | Iterable[np.ndarray], tuning: Tuning, t0_s: float = 0.0, block: int = 1 << 16
) -> list[StopEvent]:
    """Run a fresh :class:`StopDetector` over a whole recording (or an iterable of blocks)."""
    det = StopDetector(tuning, t0_s)
    events: list[StopEvent] = []
    if isinstance(samples, np.ndarray):
        for i in range(0, samples.size, block):
            events += det.feed(samples[i : i + block])
    else:
        for b in samples:
            events += det.feed(b)
    return events


def plot_levels(
    samples: np.ndarray,
    tuning: Tuning,
    t0_s: float = 0.0,
    stop_at_s: float | None = None,
    ax: Any = None,
) -> Any:
    """Plot the band level of a recording over time with the threshold and the events.

    Parameters
    ----------
    samples : numpy.ndarray
        Mono recording at ``tuning.sample_rate``.
    tuning : Tuning
        Band and threshold to show.
    t0_s : float
        Stream time of the first sample, s.
    stop_at_s : float, optional
        True stop time, s, drawn as a dashed line.
    ax : matplotlib.axes.Axes, optional
        Axes to draw on (default: a new figure).

    Returns
    -------
    matplotlib.axes.Axes
    """
    try:
        import matplotlib

        if ax is None and not has_display():
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'stickslip[plot]'") from e
    levels = frame_levels_db(samples, tuning)
    t = t0_s + (np.arange(levels.size) * tuning.hop + tuning.frame - 1) / tuning.sample_rate
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 3))
    lo, hi = tuning.band_hz
    ax.plot(t, levels, lw=0.8, label=f"band {lo:.0f}-{hi:.0f} Hz")
    ax.axhline(tuning.threshold_db, color="C3", lw=1, label="threshold")
    ax.axhline(tuning.threshold_db - tuning.hysteresis_db, color="C3", lw=0.8, ls=":", label="re-arm level")
    for i, ev in enumerate(detect(samples, tuning, t0_s=t0_s)):
        ax.axvline(ev.detected_at_s, color="C2", lw=1, label="detected" if i == 0 else None)
    if stop_at_s is not None:
        ax.axvline(stop_at_s, color="k", ls="--", lw=1, label="true stop")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"band level ({tuning.level_unit})")
    ax.legend(loc="best", fontsize="small")
    return ax
