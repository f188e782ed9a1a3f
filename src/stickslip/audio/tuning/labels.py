"""Labelled recordings for tuning: is the recording usable, and where does its sound actually change?"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import median_filter

from ..change.fit import fit_departure
from ..change.template import TEMPLATE
from ..tuningfile import TUNING_FILE

FloatArray = NDArray[np.float64]

__all__ = ["TuningError", "fmt_spans", "recording", "sound_change", "spans"]


class TuningError(ValueError):
    """The recording cannot give a usable tuning (the message says why)."""


def recording(
    samples: NDArray[np.floating] | FloatArray, sample_rate: int, stop_at_s: float, min_part_s: float, guard_s: float
) -> tuple[FloatArray, int]:
    """A labelled recording as mono float64 and its rate, or :class:`TuningError` saying what is wrong with it."""
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim == 2:
        x = x.mean(axis=1)
    if x.ndim != 1:
        raise TuningError(f"expected mono samples, got an array of shape {np.shape(samples)}")
    sample_rate = int(sample_rate)
    if (problem := TUNING_FILE.rate_problem(sample_rate)) is not None:
        raise TuningError(problem)
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        what = "samples that are not numbers" if bad.size != 1 else "sample that is not a number"
        raise TuningError(
            f"the recording holds {bad.size} {what} (NaN or "
            f"infinity), the first at {bad[0] / sample_rate:.4f} s: the file is damaged there; tune on an undamaged "
            "recording"
        )
    duration = x.size / sample_rate
    lo_ok, hi_ok = min_part_s + guard_s, duration - min_part_s - guard_s
    if not (math.isfinite(stop_at_s) and lo_ok <= stop_at_s <= hi_ok):
        if hi_ok < lo_ok:
            raise TuningError(
                f"the recording is {duration:.3f} s long; tuning needs at least "
                f"{2 * (min_part_s + guard_s):.2f} s ({min_part_s} s of stepping and of stop)"
            )
        raise TuningError(
            f"stop-at {stop_at_s:g} s must lie within {lo_ok:.3f}..{hi_ok:.3f} s of this "
            f"{duration:.3f} s recording (at least {min_part_s} s of stepping before, "
            "and of the stop after)"
        )
    return x, sample_rate


def _change_point(a: FloatArray, t_end: FloatArray, label_s: float, search_s: float, hold: int) -> float | None:
    """First time near the label from which the stop-likeness stays above 0.5 for 60 ms, s."""
    above = a >= 0.5
    n_keep = max(hold, 1)
    ok = np.flatnonzero((t_end >= label_s - search_s) & (t_end <= label_s + search_s))
    if ok.size == 0:
        return None
    # run length of 'above' from each frame on
    run = np.zeros(a.size + 1, dtype=np.int64)
    for i in range(a.size - 1, -1, -1):
        run[i] = run[i + 1] + 1 if above[i] else 0
    need = max(n_keep, int(round(0.06 / max(float(np.median(np.diff(t_end))), 1e-9))))
    starts_run = np.ones(a.size, dtype=bool)
    starts_run[1:] = ~above[:-1]  # a genuine rise, not the middle of a change that began earlier
    hits = ok[(run[ok] >= need) & starts_run[ok]]
    if hits.size == 0:
        return None
    i = int(hits[0])
    # interpolate where a crossed 0.5 between frame i-1 and i
    if i > 0 and a[i] > a[i - 1]:
        frac = (0.5 - a[i - 1]) / (a[i] - a[i - 1])
        return float(t_end[i - 1] + np.clip(frac, 0, 1) * (t_end[i] - t_end[i - 1]))
    return float(t_end[i])


def sound_change(
    V: FloatArray,
    starts: FloatArray,
    ends: FloatArray,
    stop_at_s: float,
    guard_s: float,
    edges: list[float],
    window: int,
    hold: int,
    search_s: float,
    frame: int,
    sample_rate: int,
) -> float:
    """Where the sound actually changes near the label ``stop_at_s`` (s), from a provisional signature.

    Raises :class:`TuningError` when the two parts sound alike, or nothing changes within
    ``search_s`` of the label (naming where the sound does change, if it does).
    """
    far = 0.15
    step_far = ends < stop_at_s - far
    stop_far = starts >= stop_at_s + far
    if step_far.sum() < 8 or stop_far.sum() < 8:
        step_far, stop_far = ends < stop_at_s - guard_s, starts >= stop_at_s + guard_s
    mu_step = np.percentile(V[step_far], 100 * TEMPLATE.quantile, axis=0)  # what the detector's template tracks
    sigma = np.maximum(1.4826 * np.median(np.abs(V[step_far] - np.median(V[step_far], axis=0)), axis=0), 1.0)
    delta0 = np.median(V[stop_far], axis=0) - mu_step
    strength = float(np.sqrt(np.mean((delta0 / sigma) ** 2)))
    if strength < 1.0:
        k = int(np.argmax(np.abs(delta0)))
        raise TuningError(
            f"the stepping and stopped parts sound alike: nothing changes near the labelled stop at {stop_at_s:g} s "
            f"(no sub-band of "
            f"{edges[0]:.0f}-{edges[-1]:.0f} Hz changes by more than {abs(delta0[k]):.1f} dB, "
            f"at {edges[k]:.0f}-{edges[k + 1]:.0f} Hz); check --stop-at and that the recording reaches the end stop, "
            "and switch off automatic gain control (AGC) in the sound card's or the system's settings: it levels out "
            "a stop that is only quieter"
        )
    trim_all = (len(edges) - 1) // 5
    a0, _ = fit_departure(V - mu_step, delta0, sigma, trim_all)
    a0s = np.asarray(median_filter(a0, size=window), dtype=np.float64)
    change = _change_point(a0s, ends, stop_at_s, search_s, hold)
    if change is None:
        elsewhere = _change_point(a0s, ends, stop_at_s, float(ends[-1] - ends[0]), hold)
        where = (
            f"; the sound changes at {elsewhere - 0.5 * frame / sample_rate:.3f} s"
            if elsewhere is not None and abs(elsewhere - stop_at_s) > search_s
            else ""
        )
        raise TuningError(
            f"nothing changes near the labelled stop at {stop_at_s:g} s (searched +-{search_s:g} s){where}: "
            "check --stop-at (seconds from the start of the recording) and that the joint reached its end stop"
        )
    # the change point is found on frames that end after it; its time is the frame's end minus the
    # part of the frame the stop must fill to lift a to 0.5: about half a frame
    change -= 0.5 * frame / sample_rate
    return change


def spans(mask: NDArray[np.bool_], t: FloatArray, gap_s: float = 0.05) -> list[tuple[float, float]]:
    """Merge the times where ``mask`` holds into (start, end) spans, s."""
    out: list[tuple[float, float]] = []
    for ti in t[mask]:
        if out and ti - out[-1][1] <= gap_s:
            out[-1] = (out[-1][0], float(ti))
        else:
            out.append((float(ti), float(ti)))
    return out


def fmt_spans(found: list[tuple[float, float]], limit: int = 6) -> str:
    """Spans as text ("1.20-1.45 s, ..."), at most ``limit`` of them."""
    s = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in found[:limit])
    return s + (f" and {len(found) - limit} more" if len(found) > limit else "")
