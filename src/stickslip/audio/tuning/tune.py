"""Tune the end-stop detector from a labelled recording: the spectral template (:func:`tune`).

1. The template spans the stepping sound's measured band
   (:func:`~.candidates.stepping_band`, never above 0.42 fs), cut into ``per_octave``
   sub-bands per octave.
2. Stepping is summarised per sub-band by its median level and spread (1.4826 MAD); the
   stop's *signature* is the median level of the stop part minus that of the stepping
   part, per sub-band, in dB, as the detector sees it (against a running template).
3. Where the sound actually changes is found from the signature (the first time near the
   label after which the stop-likeness stays above 0.5 for 60 ms; :mod:`.labels`); a
   disagreement with the label beyond ``label_tolerance_s`` is a warning, and the parts
   and the onset lag are then taken from the sound, not the label.
4. Candidates (:mod:`.candidates`) are scored on their *worst* frames and verified best
   first by running the detector over the recording: it must fire once, at the stop.
   ``verified`` that pass are enough, unless none of them checks what the stop lowers:
   then verification walks on to the first that does.
5. Of the passing ones, the first wins unless the self-check with injected interference
   fails clearly, or a sound that adds what the stop adds (and lowers nothing) fires it
   at more levels than another (:mod:`.verification`); a chosen template that such a
   sound fires is named in a warning.
6. Resolution (``per_octave=None``): steps 1-5 run at ``default_per_octave``. When that
   is refused, or its margin is under ``finer_below``, they run again at each of
   ``finer_per_octave``; a finer template replaces the coarser one only when its
   self-check does not fail, it separates the stop by at least ``finer_min_margin`` and
   by ``finer_gain`` more than the coarser one, on at least as many sub-bands (a stop that
   moves its modes a few per cent moves power between sub-bands 1/12 octave wide, inside
   one 1/3 octave wide). Every resolution tried is listed in ``checks["resolutions"]``.
7. The chosen tuning stores the step rate heard, the continuum between its lines per
   sub-band, and the fine continuum spectra of stepping and of the stop
   (:mod:`stickslip.audio.features.fine`): the detector predicts the stop's signature
   from them at another step rate.

The numbers are :class:`~.params.TuneParams`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..change.template import TEMPLATE
from ..events import check_step_rate
from ..features.fine import fine_range_hz, fine_segment, fine_spectrum_db
from ..features.spectra import SPECTRA, continuum_levels_db, subband_edges, subband_levels_db
from ..features.stepclock import step_rate_hz
from ..sources.guard import block_problem
from ..tuningfile import Tuning, default_frame
from .band import _DEFAULT_MAX_DIPS
from .candidates import Candidate, candidates, checks_drops, drop_threshold, make_tuning, running_template
from .candidates import stepping_band as stepping_band
from .clocks import joint_clock_only, two_clocks
from .labels import TuningError, recording, sound_change
from .params import TUNE, TuneParams
from .verification import Shared, no_template, one_stop, pick, self_check_failed

FloatArray = NDArray[np.float64]

__all__ = ["TuningError", "stepping_band", "tune"]


def tune(
    samples: NDArray[np.floating] | FloatArray,
    sample_rate: int,
    stop_at_s: float,
    joint: int | None = None,
    *,
    frame: int | None = None,
    hop: int | None = None,
    hold_s: float = TUNE.hold_s,
    release_s: float = 0.25,
    guard_s: float = 0.03,
    min_part_s: float = 0.25,
    f_min_hz: float = 300.0,
    max_stepping_s: float = 20.0,
    max_stopped_s: float = 10.0,
    per_octave: float | None = None,
    label_tolerance_s: float = 0.02,
    search_s: float = 0.5,
    self_check: bool = True,
    seed: int = 0,
    min_band_hz: float | None = None,
    step_rate_hz: float | None = None,
) -> Tuning:
    """Learn the stepping sound's spectral template and the end stop's departure from it (see the module docstring).

    Parameters
    ----------
    samples, sample_rate
        Mono recording (float, full scale 1.0; or (samples, channels), mixed to mono) and its
        rate, Hz: stepping first (the template is learned from the first 0.15 s), the stop
        at ``stop_at_s`` (s from the start), stepping against it after.
    joint, frame, hop, hold_s, release_s, guard_s, min_part_s, max_stepping_s, max_stopped_s
        The joint (stored), frame and hop (samples; default 10.7 ms and a quarter); then, s:
        before the detector fires; before it re-arms; around the stop in neither part; each
        part at least; at most analysed before and after the stop.
    f_min_hz : float
        Lowest frequency of the template, Hz (below it: hum, footsteps, doors).
    per_octave : float, optional
        Sub-bands per octave; None chooses (module docstring, 6; ``Tuning.per_octave``).
    label_tolerance_s, search_s : float
        Warn when the sound changes further than this from the label; look this far either
        side of it for the change (refuse when nothing changes there), s.
    self_check, seed, min_band_hz
        Check with seeded interference injected (``Tuning.checks``: false alarms per hour);
        ``min_band_hz`` is accepted for the version-1 command line (not used).
    step_rate_hz : float, optional
        The step rate the joint was commanded while recording, Hz (None: not told). Where the
        stepping part holds two step clocks (another instrument in bursts), the one near it is
        the joint's and the pieces the other holds are left out (:mod:`.clocks`); untold, such
        a recording is refused.

    Raises
    ------
    TuningError
        The recording is too short, the label outside it or nothing changes near it, the parts
        sound alike, or no template fires once at the stop alone (it names what spoils it)."""
    step_rate_hz = check_step_rate(step_rate_hz)
    x, sample_rate = recording(samples, sample_rate, stop_at_s, min_part_s, guard_s)
    if (problem := block_problem(x[: int(stop_at_s * sample_rate)])) is not None:
        raise TuningError(f"the stepping part of the recording is {problem}: nothing to learn from")
    y, stop_s = _one_clock(x, sample_rate, stop_at_s, step_rate_hz, min_part_s, guard_s)
    frame = int(frame or default_frame(sample_rate))
    args = _Args(sample_rate, stop_s, joint, frame, int(hop or max(1, frame // 4)), hold_s, release_s, guard_s,
                 f_min_hz, max_stepping_s, max_stopped_s, label_tolerance_s, search_s, self_check, seed)  # fmt: skip
    try:
        if per_octave is not None:
            tu, cut = _tune_at(y, args, float(per_octave))
            return _finished(y, args, replace(tu, per_octave=float(per_octave)), cut)
        return _tune_resolutions(y, args)
    except TuningError as e:
        if y is x:
            raise
        left = f"{y.size / sample_rate:.2f} s of {x.size / sample_rate:.2f} s, the stop at {stop_s:.2f} s"
        raise TuningError(f"{e} (times in what is left with the other instrument's clock left out: {left})") from e


def _one_clock(
    x: FloatArray, sample_rate: int, stop_at_s: float, told_hz: float | None, min_part_s: float, guard_s: float
) -> tuple[FloatArray, float]:
    """The recording ``x`` and its label, with one step clock in its stepping part: as it is where it holds one;
    where it holds two, refused untold, else without the pieces the other holds (:mod:`.clocks`)."""
    clocks = two_clocks(x[: int((stop_at_s - TUNE.clock_end_s) * sample_rate)], sample_rate)
    if clocks is None:
        return x, stop_at_s
    if told_hz is None:  # which clock is the joint's is not known
        raise TuningError(f"the stepping part of the recording {_two(clocks)}: the stop's sound cannot be told from it")
    y, stop_s = joint_clock_only(x, sample_rate, stop_at_s, clocks, told_hz)
    y, _ = recording(y, sample_rate, stop_s, min_part_s, guard_s)
    if (problem := other_clock(y[: int((stop_s - TUNE.clock_end_s) * sample_rate)], sample_rate)) is not None:
        raise TuningError(f"the stepping part of the recording {problem}; left out where heard, it still does")
    return y, stop_s


def other_clock(x: FloatArray, sample_rate: int, p: TuneParams = TUNE) -> str | None:
    """What says another instrument steps in the stepping part ``x`` (None: one clock heard), in words.

    The step rate is heard again in pieces ``clock_piece_s`` long (where its line is
    ``clock_min_db`` clear): a joint's clock holds throughout (drifting at most a few per
    cent), so a piece heard ``clock_off`` or more from the pieces' median rate and from its
    harmonics and fractions is another instrument's (a second stick-slip arm stepping in
    bursts, louder than the joint while it steps: the tuning learnt its clock and its
    bursts' coming and going as the stop).
    """
    clocks = two_clocks(x, sample_rate, p)
    return None if clocks is None else _two(clocks)


def _two(clocks: tuple[float, float]) -> str:
    """What a recording holding the step clocks ``clocks`` (Hz, :func:`.clocks.two_clocks`) is told it holds."""
    lo, hi = sorted(clocks)
    return f"holds two step clocks ({lo:.0f} Hz and {hi:.0f} Hz, in turns): another instrument"


@dataclass(frozen=True)
class _Args:
    """:func:`tune`'s settings, as one resolution's tuning uses them."""

    sample_rate: int
    stop_at_s: float
    joint: int | None
    frame: int
    hop: int
    hold_s: float
    release_s: float
    guard_s: float
    f_min_hz: float
    max_stepping_s: float
    max_stopped_s: float
    label_tolerance_s: float
    search_s: float
    self_check: bool
    seed: int
    range_db: float = TUNE.range_db
    p: TuneParams = TUNE
    #: the sounds every candidate hears and their frames' spectra, made once per tuning
    shared: Shared = field(default_factory=Shared, compare=False)


def _tried(tu: Tuning, po: float, **more: Any) -> tuple[bool, dict[str, Any]]:
    """Whether ``tu``'s self-check failed, and the row of ``checks["resolutions"]`` that says how it fared."""
    failed = self_check_failed(tu.checks or {})
    row = {"per_octave": po, **more, "sub_bands": len(tu.signature_db or ()), "margin": tu.margin_db}
    return failed, {**row, "self_check_failed": failed}


def _tune_resolutions(x: FloatArray, args: _Args) -> Tuning:
    """Tune at ``default_per_octave``, and at ``finer_per_octave`` where that is refused or weak (module docstring)."""
    p = args.p
    tried: list[dict[str, Any]] = []
    best: tuple[Tuning, _Cut] | None = None
    first_error: TuningError | None = None
    for po in (p.default_per_octave, *p.finer_per_octave):
        if best is not None and po != p.default_per_octave and (best[0].margin_db or 0.0) >= p.finer_below:
            break
        try:
            tu, cut = _tune_at(x, args, po)
        except TuningError as e:
            first_error = first_error or e
            tried.append({"per_octave": po, "refused": str(e)[:200]})
            continue
        tu = replace(tu, per_octave=po)
        failed, row = _tried(tu, po)
        tried.append(row)
        if best is None:
            if po == p.default_per_octave or (not failed and (tu.margin_db or 0.0) >= p.finer_min_margin):
                best = tu, cut
        elif (
            not failed
            and (tu.margin_db or 0.0) >= max(p.finer_min_margin, (best[0].margin_db or 0.0) + p.finer_gain)
            and len(tu.signature_db or ()) >= len(best[0].signature_db or ())
        ):
            best = tu, cut
    if best is None and p.wide_range_db is not None:
        best = _tune_wide(x, args, p.wide_range_db, tried)
    if best is None:
        assert first_error is not None
        raise first_error
    checks = dict(best[0].checks or {})
    checks["resolutions"] = tried
    return _finished(x, args, replace(best[0], checks=checks), best[1])


def _tune_wide(x: FloatArray, args: _Args, range_db: float, tried: list[dict[str, Any]]) -> tuple[Tuning, _Cut] | None:
    """Every resolution refused: a stop that moves the modes at the band's edge out of it is heard beyond it."""
    po = args.p.default_per_octave
    try:
        tu, cut = _tune_at(x, replace(args, range_db=range_db), po)
    except TuningError as e:
        tried.append({"per_octave": po, "range_db": range_db, "refused": str(e)[:200]})
        return None
    tu = replace(tu, per_octave=po)
    failed, row = _tried(tu, po, range_db=range_db)
    tried.append(row)
    return (tu, cut) if not failed and (tu.margin_db or 0.0) >= args.p.finer_min_margin else None


@dataclass(frozen=True)
class _Parts:
    """A labelled recording measured at one resolution: its frames, the two parts, the signature."""

    first: int
    last: int
    edges: list[float]
    ends: FloatArray
    stop_s: float
    g: float
    change: float
    stepping: NDArray[np.bool_]
    sigma: FloatArray
    D: FloatArray
    delta: FloatArray
    mu_step: FloatArray
    cands: list[Candidate]
    warnings: list[str]


def _parts(x: FloatArray, args: _Args, per_octave: float) -> _Parts:
    """Steps 1-4 of the module docstring: the sub-bands, where the sound changes, the parts, the candidates."""
    sr, stop_at_s, frame, hop, guard_s = args.sample_rate, args.stop_at_s, args.frame, args.hop, args.guard_s
    hold = max(1, int(math.ceil(args.hold_s * sr / hop - 1e-9)))
    window = hold + _DEFAULT_MAX_DIPS
    first = max(0, int((stop_at_s - args.max_stepping_s) * sr) // hop * hop)
    last = min(x.size, int((stop_at_s + args.max_stopped_s) * sr))
    f_lo, f_hi = stepping_band(x[first : int((stop_at_s - 0.15) * sr)], sr, frame, hop, args.f_min_hz,
                               range_db=args.range_db)  # fmt: skip
    edges = subband_edges(f_lo, f_hi, sr, frame, per_octave)
    V = subband_levels_db(x[first:last], sr, frame, hop, edges, args.shared.powers)
    starts = first / sr + np.arange(V.shape[0]) * hop / sr
    ends = starts + (frame - 1) / sr
    # where the sound changes (from a provisional signature of frames well away from the label)
    change = sound_change(V, starts, ends, stop_at_s, guard_s, edges, window, hold, args.search_s, frame, sr)
    warnings: list[str] = []
    stop_s = stop_at_s
    if abs(change - stop_at_s) > args.label_tolerance_s:
        warnings.append(
            f"the labelled stop ({stop_at_s:.3f} s) disagrees with the sound, which changes at "
            f"{change:.3f} s ({1e3 * (change - stop_at_s):+.0f} ms); tuned on the sound's change"
        )
        stop_s = change
    g = max(guard_s, abs(change - stop_at_s) + guard_s) if stop_s == stop_at_s else guard_s
    stepping, stopped = ends < stop_s - g, starts >= stop_s + g
    if stepping.sum() < 2 * TEMPLATE.chunk or stopped.sum() < window:
        raise TuningError(f"too little stepping before or stop after {stop_s:.3f} s to tune on")
    sigma = np.maximum(1.4826 * np.median(np.abs(V[stepping] - np.median(V[stepping], axis=0)), axis=0), 1.0)
    # departures as the detector sees them: from a template that follows the stepping sound (a causal running low
    # quantile over tau_s), frozen at the stop
    base = running_template(V, stepping, hop / sr)
    D = V - base
    delta = np.median(D[stopped], axis=0)
    cands = candidates(D, sigma, delta, stepping, stopped, hold, window, args.p)
    if not cands:
        raise TuningError("no sub-band of the stepping sound changes at the stop")
    # the whole template first unless a sub-range separates clearly better: more sub-bands, more to tell a stop from
    # a voice or a second instrument by
    cands.sort(key=lambda c: (c.name != "all sub-bands" or c.margin < args.p.whole_margin, -c.margin))
    mu_step = base[int(np.flatnonzero(stepping)[-1])]
    return _Parts(first, last, edges, ends, stop_s, g, change, stepping, sigma, D, delta, mu_step, cands, warnings)


def _verify(x: FloatArray, args: _Args, pt: _Parts) -> list[tuple[Tuning, float, float]]:
    """Verify the candidates best first: each must fire once, at the stop (with its onset lag and latency)."""
    p, sr = args.p, args.sample_rate
    hold = max(1, int(math.ceil(args.hold_s * sr / args.hop - 1e-9)))
    window = hold + _DEFAULT_MAX_DIPS
    passing: list[tuple[Tuning, float, float]] = []
    failures: list[str] = []
    for cand in pt.cands[: p.max_candidates]:
        if cand.margin <= p.min_margin:
            break
        tu = make_tuning(cand, pt.edges, pt.delta, pt.sigma, sr, args.frame, args.hop, args.hold_s, args.release_s,
                         args.joint, pt.mu_step)  # fmt: skip
        b0, b1 = cand.bands[0], cand.bands[-1] + 1
        tu = replace(tu, drop_threshold=drop_threshold(pt.D[:, b0:b1], pt.sigma[b0:b1], pt.stepping, hold, window, p))
        events = one_stop(tu, args.shared.powers).feed(x)
        near = [e for e in events if pt.stop_s - pt.g <= e.detected_at_s <= pt.stop_s + 0.2]
        if len(events) == 1 and len(near) == 1:
            ev = near[0]
            passing.append((tu, ev.onset_s - pt.stop_s, ev.detected_at_s - pt.stop_s))
            # enough to choose from, unless every one relies on the stop's rises alone: a sound that adds the same
            # looks like it; walk on to the first that also checks what the stop lowers (the self-check decides)
            if len(passing) >= p.verified and any(checks_drops(t) for t, _, _ in passing):
                break
        else:
            where = ", ".join(f"{e.detected_at_s:.3f} s" for e in events[:6]) or "never"
            failures.append(f"{cand.name} fired {where}")
    if not passing:
        raise no_template(pt.cands[0], pt.D, pt.delta, pt.sigma, hold, window, pt.stepping, pt.ends, failures)
    return passing


@dataclass(frozen=True)
class _Cut:
    """Where a resolution's tuning found the parts (samples ``first`` to ``last``, the stop at ``stop_s`` +- ``g``)."""

    first: int
    last: int
    stop_s: float
    g: float


def _tune_at(x: FloatArray, args: _Args, per_octave: float) -> tuple[Tuning, _Cut]:
    """Steps 1-5 of the module docstring at ``per_octave`` sub-bands per octave (step 7: :func:`_finished`)."""
    pt = _parts(x, args, per_octave)
    passing = _verify(x, args, pt)
    # the self-check with interference; the quietest passing candidate wins
    tu = pick(passing, x, args.sample_rate, args.frame, pt.stop_s, pt.g, args.seed, args.self_check, pt.warnings,
              args.stop_at_s, pt.change, args.shared)  # fmt: skip
    return tu, _Cut(pt.first, pt.last, pt.stop_s, pt.g)


def _finished(x: FloatArray, args: _Args, tu: Tuning, cut: _Cut) -> Tuning:
    """Step 7 of the module docstring, for the chosen resolution only (nothing in the choice reads it)."""
    sr, p = args.sample_rate, args.p
    stop_s, g, first, last = cut.stop_s, cut.g, cut.first, cut.last
    # the step rate, and the continuum between its lines: how a stream at another rate tells it began at the stop
    tu = _with_continuum(tu, x[first : int((stop_s - g) * sr)], x[int((stop_s + g) * sr) : last])
    # the fine continuum spectra: the stop's signature predicted at another step rate
    step_hi, skip = int((stop_s - g) * sr), int(p.fine_skip_s * sr)
    step_lo = first + skip if step_hi - (first + skip) >= 2 * fine_segment(sr) else first
    stop_lo = int((stop_s + p.fine_skip_stop_s) * sr)
    if last - stop_lo < fine_segment(sr):
        stop_lo = int((stop_s + g) * sr)
    return _with_fine(tu, x[step_lo:step_hi], x[stop_lo:last])


def _with_fine(tu: Tuning, stepping: FloatArray, stopped: FloatArray) -> Tuning:
    """``tu`` with the fine continuum spectra of stepping and of the stop (:func:`~..features.fine.fine_spectrum_db`).

    Over the sub-bands and a few detector bins beyond, at the step rate ``tu`` heard; levels
    rounded to 0.01 dB. Unchanged when no rate was heard or a part is shorter than one
    Welch segment.
    """
    assert tu.edges_hz is not None
    if tu.step_rate_hz is None:
        return tu
    lo, hi = fine_range_hz(tu.edges_hz, tu.sample_rate, tu.frame)
    step = fine_spectrum_db(stepping, tu.sample_rate, tu.step_rate_hz, lo, hi)
    stop = fine_spectrum_db(stopped, tu.sample_rate, tu.step_rate_hz, lo, hi)
    if step is None or stop is None:
        return tu
    return replace(
        tu,
        fine_start_hz=round(step[0], 6),
        fine_bin_hz=round(step[1], 9),
        fine_stepping_db=tuple(round(float(v), 2) for v in step[2]),
        fine_stopped_db=tuple(round(float(v), 2) for v in stop[2]),
    )


def _with_continuum(tu: Tuning, stepping: FloatArray, stopped: FloatArray) -> Tuning:
    """``tu`` with the step rate heard while stepping and the continuum's levels, signature and spread.

    The continuum (:func:`~stickslip.audio.features.spectra.continuum_levels_db`) is the
    power between the step clock's lines: per sub-band, its low quantile over the stepping
    part (as the detector's template), the same quantile of the stopped part less it, and
    the stepping frames' robust spread (at least 1 dB). Unchanged when no step rate is heard.
    """
    assert tu.edges_hz is not None
    rate = step_rate_hz(stepping, tu.sample_rate)
    if not math.isfinite(rate) or stepping.size < tu.frame or stopped.size < tu.frame:
        return tu
    frame = SPECTRA.continuum_frame * tu.frame
    Cs = continuum_levels_db(stepping, tu.sample_rate, frame, tu.frame, tu.edges_hz, rate)
    Cp = continuum_levels_db(stopped, tu.sample_rate, frame, tu.frame, tu.edges_hz, rate)
    q = 100 * TEMPLATE.quantile
    with np.errstate(all="ignore"):
        ok = np.isfinite(Cs).all(axis=0) & np.isfinite(Cp).all(axis=0)
        level = np.full(Cs.shape[1], np.nan)
        sig = np.full(Cs.shape[1], np.nan)
        spread = np.full(Cs.shape[1], np.nan)
        if ok.any():
            level[ok] = np.percentile(Cs[:, ok], q, axis=0)
            sig[ok] = np.percentile(Cp[:, ok], q, axis=0) - level[ok]
            mad = np.median(np.abs(Cs[:, ok] - np.median(Cs[:, ok], axis=0)), axis=0)
            spread[ok] = np.maximum(1.4826 * mad, 1.0)

    def r(v: FloatArray) -> tuple[float, ...]:
        return tuple(round(float(e), 3) if math.isfinite(e) else math.nan for e in v)

    return replace(
        tu,
        step_rate_hz=round(float(rate), 3),
        continuum_levels_db=r(level),
        continuum_signature_db=r(sig),
        continuum_spread_db=r(spread),
    )
