"""Verifying template candidates: the refusal that names what spoils them, and the self-check.

A candidate that fires once, at the stop, on its own recording is checked again with
interference injected (:mod:`.inject`: knocks, babble, a second click train, +-20 dB of
gain) and with a sound that adds what the stop adds and lowers nothing (``mimic_*``): the
first that neither clearly fails nor is mimicked wins (:func:`pick`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..change import TemplateDetector
from ..change.fit import fit_departure
from ..features.spectra import FramePowers, subband_levels_db
from ..paramfield import param
from ..tuningfile import Tuning
from . import inject
from .candidates import Candidate, decided
from .labels import TuningError, fmt_spans, spans

__all__ = ["VERIFY", "Shared", "VerifyParams", "no_template", "one_stop", "pick", "self_check_failed"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class VerifyParams:
    """The self-check's sound that adds what the stop adds (and lowers nothing)."""

    mimic_levels_db: tuple[float, ...] = param(
        (-6.0, 0.0, 6.0), "dB re the stop's rise", "its levels: below, at and above the rise itself"
    )
    mimic_bursts_s: tuple[float, ...] = param((0.06, 0.3, 1.0), "s", "its bursts: a syllable, a word, a sentence")
    mimic_start_s: float = param(0.45, "s", "the bursts start this long into the recording (after the warm-up) ...")
    mimic_gap_s: float = param(0.4, "s", "... and this far apart")


VERIFY = VerifyParams()


def one_stop(tu: Tuning, powers: FramePowers | None = None) -> TemplateDetector:
    """A detector judged as tuning always has: after a fire it stays latched until *a* stays low.

    The end-of-stop re-arming (:mod:`stickslip.audio.change.release`) is for a session with
    several stops; the tuning's recordings hold one, and its self-check counts fires on
    interference bursts as they were counted when its rules were measured.
    """
    det = TemplateDetector(tu)
    det.hold(True)
    det.powers = powers  # the frames' spectra of the sounds every candidate hears, computed once
    return det


def no_template(
    best: Candidate,
    D: FloatArray,
    delta: FloatArray,
    sigma: FloatArray,
    hold: int,
    window: int,
    stepping: NDArray[np.bool_],
    ends: FloatArray,
    failures: list[str],
) -> TuningError:
    """The refusal when no candidate verified: which time spans of the stepping sound like the stop."""
    sub = list(best.bands)
    a, rho = fit_departure(D[:, sub], delta[sub], sigma[sub], best.trim)
    dec = decided(a, rho, best.residual_max, hold, window)
    bad = stepping & (dec >= min(best.threshold, 0.5))
    found = spans(bad, ends)
    hint = (
        f"the stepping part sounds like the stop at {fmt_spans(found)}"
        if found
        else "the stop does not stay distinct long enough"
    )
    return TuningError(
        f"no template both stays quiet while stepping and fires once at the stop ({'; '.join(failures[:3])}); "
        f"{hint}: cut those spans out of the recording or record again"
    )


def self_check_failed(checks: dict[str, Any]) -> bool:
    """The self-check (``Tuning.checks``) failed clearly: more than one false alarm with interference injected, or a
    stop missed (False when no self-check ran)."""
    return bool(checks.get("false_alarms", 0) > 1 or checks.get("stops_found") != checks.get("stops"))


def pick(
    passing: list[tuple[Tuning, float, float]],
    x: FloatArray,
    sample_rate: int,
    frame: int,
    stop_s: float,
    g: float,
    seed: int,
    self_check: bool,
    warnings: list[str],
    stop_at_s: float,
    change: float,
    shared: Shared | None = None,
) -> Tuning:
    """Of the verified candidates, the first whose self-check neither clearly fails nor is mimicked by added sound.

    ``passing`` holds each candidate with its onset lag and latency on the recording ``x``
    (stop at ``stop_s``, guard ``g``). The ranking stands unless the self-check with
    interference fails clearly (more than one false alarm, or a stop missed) or a sound
    shaped like the stop's own rise fires the candidate (:func:`_rise_mimicry`) at more of
    its levels than a later one: a tuning that also checks what the stop lowers cannot be
    fooled by a sound that only adds. Its onset lag and latency are the medians over the
    clean and the injected runs; the self-check, the warnings and both stop times (labelled
    ``stop_at_s``, heard ``change``) go into ``Tuning.checks``.
    """
    results: list[tuple[int, int, int, Tuning, float, float, dict[str, Any]]] = []
    for tu, lag, lat in passing:
        checks: dict[str, Any] = _self_check(tu, x, sample_rate, stop_s, g, seed, shared) if self_check else {}
        failed = int(self_check_failed(checks))
        mimicked = 0
        if self_check and not failed:
            checks["rise_mimic"] = _rise_mimicry(tu, x, sample_rate, stop_s, g, seed, shared)
            mimicked = int(sum(checks["rise_mimic"].values()))
        results.append((failed, mimicked, len(results), tu, lag, lat, checks))
        if not failed and not mimicked:
            break
    results.sort(key=lambda r: (r[0], r[1], r[2]))
    _, mimicked, _, tu, lag, lat, checks = results[0]
    checks = dict(checks)
    # the onset lag and latency from every run that found the stop (one recording's crossing can
    # be nudged by a syllable or a knock; the median of the clean and the injected runs is not)
    lag = float(np.median([lag, *checks.pop("onset_lags_s", [])]))
    lat = float(np.median([lat, *checks.pop("latencies_s", [])]))
    # frames end after the samples they hold: the crossing cannot come before the onset, nor later than a
    # frame after it (a negative lag means something in the recording rose before the stop did)
    lag = float(np.clip(lag, 0.0, frame / sample_rate))
    # ... and a stop heard before its label (a stop that arrives over a few steps, the label at the last) was heard at
    # once: a latency is not negative (it was, and the tuning file refused it: a traceback from tune)
    lat = float(np.clip(lat, 0.0, 1.0))
    checks["warnings"] = warnings
    checks["stop_at_label_s"] = float(stop_at_s)
    checks["stop_at_sound_s"] = round(float(change), 4)
    _warn(tu, checks, warnings, self_check, bool(mimicked))
    return replace(tu, onset_lag_s=round(lag, 6), latency_measured_s=round(lat, 6), checks=checks)


def _warn(tu: Tuning, checks: dict[str, Any], warnings: list[str], self_check: bool, mimicked: bool) -> None:
    """The self-check's warnings: false alarms with interference injected, a sound that adds what the stop adds."""
    if self_check and checks.get("false_alarms", 0):
        warnings.append(
            f"with interference injected the detector gave {checks['false_alarms']} false alarms in "
            f"{checks['checked_s']:.0f} s (about {checks['false_alarms_per_hour']:.0f} per hour)"
        )
    if mimicked:
        lo, hi = tu.band_hz
        at = ", ".join(k for k, v in checks["rise_mimic"].items() if v)
        warnings.append(
            f"a sound that adds what the stop adds in {lo:.0f}-{hi:.0f} Hz and lowers nothing fired the detector in "
            f"the self-check ({at} re the stop's rise): a voice, a tap or another instrument there can look like the "
            "stop (listen confirms a stop by its persistence; keep such sounds away from the microphone)"
        )


def _rise_mimicry(
    tu: Tuning, x: FloatArray, sample_rate: int, stop_s: float, guard_s: float, seed: int, shared: Shared | None = None
) -> dict[str, int]:
    """Fires of ``tu`` on the stepping part with a sound added that does what the stop does where it adds sound.

    Per sub-band of the tuning, noise with the power the stop adds there (the stepping
    part's mean power times ``10**(signature/10) - 1`` where the signature is positive;
    nothing where the stop lowers the sound), in bursts of ``mimic_bursts_s``, at each of
    ``mimic_levels_db`` (:class:`VerifyParams`). A tuning whose stop signature has drops worth
    checking (:mod:`stickslip.audio.change.drops`) is seldom fired by it: no added sound lowers a sub-band
    (a faint one asks for drops in proportion, which drops only just worth checking can
    meet by the stepping's wobble). One that relies on rises alone is, and so it is, in a
    room, by a voice, a tap or another instrument in those sub-bands. Returns the fires
    per level (empty when the stepping part is too short to hold a burst).
    """
    p = VERIFY
    assert tu.edges_hz is not None and tu.signature_db is not None
    end_s = stop_s - guard_s - 0.05
    spans: list[tuple[float, float]] = []
    t = p.mimic_start_s
    for d in p.mimic_bursts_s:
        d = min(d, end_s - t)
        if d < 0.05:
            break
        spans.append((t, d))
        t += d + p.mimic_gap_s
    if not spans:
        return {}
    n_step = int((stop_s - guard_s) * sample_rate)
    powers = None if shared is None else shared.powers  # the recording's spectra, computed once
    V = subband_levels_db(x[:n_step], sample_rate, tu.frame, tu.hop, tu.edges_hz, powers)
    power = np.mean(10.0 ** (V / 10.0), axis=0)
    added = power * (10.0 ** (np.maximum(np.asarray(tu.signature_db, dtype=np.float64), 0.0) / 10.0) - 1.0)
    n = min(x.size, n_step)
    rng = np.random.default_rng([seed, 7])
    noise = inject.shaped_noise(n, sample_rate, tu.edges_hz, added, rng) * inject.bursts(n, sample_rate, spans)
    out: dict[str, int] = {}
    for level in p.mimic_levels_db:
        y = x[:n] + noise * 10.0 ** (level / 20.0)
        out[f"{level:+.0f} dB"] = len(one_stop(tu).feed(y))
    return out


class Shared:
    """What a tuning's candidates share, at every resolution: the same sounds, made and measured once.

    The self-check's interference is seeded and scaled to the stepping's level in the
    candidate's band: candidates with the same band hear the same sounds. Their frames'
    spectra (:class:`~..features.spectra.FramePowers`) and the sounds themselves are kept
    for one recording ``x`` (forgotten when another is given).
    """

    def __init__(self) -> None:
        self.powers = FramePowers()
        self._x: FloatArray | None = None
        self._rms: dict[tuple[float, float, int, int], float] = {}
        self._sounds: dict[tuple[float, int, int], dict[str, FloatArray]] = {}

    def variants(self, x: FloatArray, sample_rate: int, band_hz: tuple[float, float], n_stop: int, seed: int
                 ) -> dict[str, FloatArray]:  # fmt: skip
        """The recording ``x`` with each interference injected (:mod:`.inject`), and at +-20 dB of gain."""
        if x is not self._x:
            self._x, self._rms, self._sounds = x, {}, {}
        lo, hi = band_hz
        if (lo, hi, n_stop, sample_rate) not in self._rms:
            from scipy.signal import butter, sosfilt

            sos = butter(4, [lo, min(hi, 0.49 * sample_rate)], btype="band", fs=sample_rate, output="sos")
            self._rms[lo, hi, n_stop, sample_rate] = float(np.sqrt(np.mean(sosfilt(sos, x[:n_stop]) ** 2)))
        rms = self._rms[lo, hi, n_stop, sample_rate]
        if (rms, seed, sample_rate) not in self._sounds:
            rng = np.random.default_rng(seed)
            n = x.size
            self._sounds[rms, seed, sample_rate] = {
                "knocks": x + inject.knocks(n, sample_rate, rms, rng),
                "babble": x + inject.babble(n, sample_rate, rms, rng),
                "second click train": x + inject.click_train(n, sample_rate, rms, rng),
                "gain +20 dB": x * 10.0,
                "gain -20 dB": x * 0.1,
            }
        return self._sounds[rms, seed, sample_rate]


def _self_check(
    tu: Tuning, x: FloatArray, sample_rate: int, stop_s: float, guard_s: float, seed: int,
    shared: Shared | None = None,
) -> dict[str, Any]:  # fmt: skip
    """Run ``tu`` on the recording with interference injected; count false alarms and stops found."""
    shared = shared or Shared()
    powers = shared.powers
    variants = shared.variants(x, sample_rate, tu.band_hz, int(stop_s * sample_rate), seed)
    false_alarms = 0
    found = 0
    lat: list[float] = []
    lags: list[float] = []
    per: dict[str, int] = {}
    for name, y in variants.items():
        events = one_stop(tu, powers).feed(y)
        hits = [e for e in events if stop_s - guard_s <= e.detected_at_s <= stop_s + 0.2]
        fa = len(events) - min(1, len(hits))
        per[name] = fa
        false_alarms += fa
        if hits:
            found += 1
            lat.append(hits[0].detected_at_s - stop_s)
            lags.append(hits[0].onset_s - stop_s)
    checked_s = len(variants) * stop_s
    return {
        "false_alarms": false_alarms,
        "checked_s": round(checked_s, 3),
        "false_alarms_per_hour": round(false_alarms / checked_s * 3600.0, 1),
        "false_alarms_by_interference": per,
        "stops": len(variants),
        "stops_found": found,
        "latency_median_s": round(float(np.median(lat)), 4) if lat else None,
        "onset_lags_s": [round(v, 5) for v in lags],
        "latencies_s": [round(v, 5) for v in lat],
    }
