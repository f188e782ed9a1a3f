"""A stop that only shifts the spectrum (issue 10, round 9b).

A contact that pins the arm moves its modes up a few per cent with the same energy: a 4 %
shift is 1/17 octave, so 1/3-octave sub-bands see it only where a mode sits at a band edge.
``tune`` now tries 6 and 12 sub-bands per octave where 3 are refused or separate the stop
weakly, and a wider band where every resolution is refused
(:func:`stickslip.audio.tuning.tune`, Notes 7). Checked on two generators:

* the fifth (``tests/support/arrival_sound.py``, ``shifted``: five modes all 4-12 % up), whose
  arms 3, 4 and 5 the change moves (arm 4 was refused, arms 3 and 5 tuned at 3 per octave);
* a sixth, written for this round and never tuned to (``tests/support/beam_sound.py``: a slender
  clamped-free beam whose tip the stop pins; modes of order 10-50 move up by about
  ``1.5 / n``, 3-13 %, their shapes with them; each slip an impulse).

Outcomes are counted as a traverse counts: the confirmed first event's onset within 25 ms
is *right*; flagged ``onset_uncertain`` is a refusal (measure again); more than 25 ms off
without the flag is *silently wrong*; no event is *missed* (safe: the traverse times out).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import arrival_sound as ar
import beam_sound as bm
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.confirm import ConfirmedStopDetector
from stickslip.audio.detector import detector_for
from stickslip.audio.tuning import TuneParams, TuningError
from stickslip.audio.tuningfile import Tuning, TuningFileError
from test_audio_rate_signature import tuned_alone

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000
TOL_S = 0.025


def _outcome(tu: Tuning, y: np.ndarray, stop_at: float) -> tuple[str, list[float]]:
    """right / flagged / early / late / missed, and every event's onset less the stop, s."""
    det = ConfirmedStopDetector(detector_for(tu))
    events = det.feed(np.asarray(y, dtype=np.float32)) + det.finish()
    onsets = [e.onset_s - stop_at for e in events]
    if not events:
        return "missed", onsets
    if events[0].onset_uncertain:
        return "flagged", onsets
    err = onsets[0]
    return ("early" if err < -TOL_S else "late" if err > TOL_S else "right"), onsets


def _resolutions(tu: Tuning) -> list[dict[str, Any]]:
    """What tune tried, in order (``checks["resolutions"]``)."""
    assert tu.checks is not None
    out: list[dict[str, Any]] = tu.checks["resolutions"]
    return out


@cache
def _arrival_tuning(arm: int) -> Tuning:
    return tune(ar.render(ar.tuning_scene(ar.Arm(arm, "shifted"))), SR, 2.0)


def _arrival_draws(arm: int, n: int = 12) -> list[ar.Scene]:
    """``n`` recordings of the arm's shifted stop within the tuning's domain: rate 1000 Hz +-5 %, arrival over 1-11
    steps, jitter 0.2-3 %, a room of T60 0.05-0.3 s at -18 to -9 dB, SNR 25-40 dB, no burst (the onset test's)."""
    rng = np.random.default_rng(500 + arm)
    return [
        ar.Scene(
            arm=ar.Arm(arm, "shifted"),
            rate=float(rng.uniform(950, 1050)),
            stop_at=float(rng.uniform(1.5, 2.5)),
            dur=3.5,
            arrive_steps=int(rng.integers(1, 12)),
            jitter=float(rng.uniform(0.002, 0.03)),
            wander=0.0,
            t60_s=float(rng.uniform(0.05, 0.3)),
            reverb_db=float(rng.uniform(-18, -9)),
            snr_db=float(rng.uniform(25, 40)),
            burst="none",
            seed=int(rng.integers(1, 10**6)),
        )  # fmt: skip
        for _ in range(n)
    ]


def _count(tu: Tuning, scenes: list[ar.Scene] | list[bm.Scene], render: object) -> dict[str, int]:
    out = dict.fromkeys(("right", "flagged", "early", "late", "missed"), 0)
    for s in scenes:
        assert s.stop_at is not None
        kind, onsets = _outcome(tu, render(s), s.stop_at)  # type: ignore[operator]  # ar.render or bm.render
        out[kind] += 1
        # no unflagged event in the stepping before the stop
        assert kind in ("flagged", "missed") or all(o >= -TOL_S for o in onsets), (s, onsets)
    return out


# ---------------------------------------------------------------- the fifth generator, shifted stop


def test_arm_4s_shifted_stop_is_tuned_and_heard() -> None:
    """Refused before (no 1/3-octave sub-band of 375-4219 Hz changed by more than 5 dB): the 4.19 kHz mode leaves
    that band at the stop (to 4.50 kHz). Now tuned over the band 45 dB wide and heard in most recordings, none
    silently wrong. Measured on these 12: 7 right, 1 flagged, 4 missed."""
    tu = _arrival_tuning(4)
    res = _resolutions(tu)
    assert [r["per_octave"] for r in res[:3]] == [TuneParams().default_per_octave, *TuneParams().finer_per_octave]
    assert "refused" in res[0] and "refused" in res[1]  # 3 and 6 per octave: the stop changes too little
    assert res[-1]["range_db"] == 45.0 and res[-1]["margin"] == pytest.approx(tu.margin_db)
    assert (
        tu.per_octave == TuneParams().default_per_octave and tu.edges_hz is not None and tu.edges_hz[-1] > 4500.0
    )  # past where the mode went
    c = _count(tu, _arrival_draws(4), ar.render)
    assert c["early"] == c["late"] == 0, c
    assert c["right"] >= 6, c  # measured 7


@pytest.mark.parametrize(("arm", "chosen", "right_at_3"), [(3, 12.0, 11), (5, 6.0, 11)])
def test_a_weakly_separated_shifted_stop_takes_finer_sub_bands(arm: int, chosen: float, right_at_3: int) -> None:
    """Arms 3 and 5: at 3 per octave the stop separates by 0.54 and 0.64 (stop-likeness); at 12 and 6 per octave by
    0.78 and 0.84, and that template is kept. Measured on 12 recordings each: arm 3 11 on time and one flagged (as at 3
    per octave), arm 5 all 12 on time (at 3 per octave 11, one missed); none silently wrong."""
    tu = _arrival_tuning(arm)
    assert tu.per_octave == chosen
    margins = {r["per_octave"]: r["margin"] for r in _resolutions(tu)}
    assert margins[chosen] >= margins[TuneParams().default_per_octave] + 0.2
    c = _count(tu, _arrival_draws(arm), ar.render)
    assert c["early"] == c["late"] == 0, c
    assert c["right"] >= right_at_3, c  # measured 11 and 12


def test_a_strong_template_keeps_three_sub_bands_per_octave() -> None:
    """Arm 2's shifted stop separates by 0.83 at 3 per octave: no finer resolution is tried, the tuning is the one an
    explicit ``per_octave=3`` gives."""
    x = ar.render(ar.tuning_scene(ar.Arm(2, "shifted")))
    auto = tune(x, SR, 2.0)
    assert [r["per_octave"] for r in _resolutions(auto)] == [TuneParams().default_per_octave]
    fixed = tune(x, SR, 2.0, per_octave=3)
    assert auto.edges_hz == fixed.edges_hz and auto.signature_db == fixed.signature_db
    assert auto.threshold_db == fixed.threshold_db and auto.per_octave == fixed.per_octave == 3.0


def test_a_recording_where_nothing_changes_is_still_refused() -> None:
    """Every resolution, and the wide band, refuse a recording that steps on past its label: the message is the
    3-per-octave one, as before."""
    x = ar.render(ar.Scene(arm=ar.Arm(2, "shifted"), stop_at=None, dur=3.5, seed=7))
    with pytest.raises(TuningError, match="nothing changes near the labelled stop"):
        tune(x, SR, 2.0)


# ---------------------------------------------------------------- the tuning file


def test_the_chosen_resolution_round_trips_and_old_files_load(tmp_path: object) -> None:
    tu = _arrival_tuning(3)
    d = tu.to_dict()
    assert d["per_octave"] == 12.0 and d["checks"]["resolutions"][-1]["per_octave"] == 12.0
    back = Tuning.from_dict(d)
    assert back == tu and back.per_octave == 12.0
    assert "(12 per octave)" in back.report()
    old = {k: v for k, v in d.items() if k != "per_octave"}  # a file written before round 9b
    assert Tuning.from_dict(old).per_octave is None and "per octave" not in Tuning.from_dict(old).report()
    for bad in (0, -3, 100, "12", True, float("nan")):
        with pytest.raises(TuningFileError, match="per_octave"):
            Tuning.from_dict({**d, "per_octave": bad})


# ---------------------------------------------------------------- the sixth generator: a beam pinned at its tip


def test_the_beams_modes_are_the_textbook_roots() -> None:
    """Clamped-free 1.8751, 4.6941, 7.8548, 10.9955; clamped-pinned 3.9266, 7.0686, 10.2102 (beta L)."""
    np.testing.assert_allclose(bm.roots(False, 4), [1.875104, 4.694091, 7.854757, 10.995541], atol=1e-5)
    np.testing.assert_allclose(bm.roots(True, 3), [3.926602, 7.068583, 10.210176], atol=1e-5)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(1, 10**6))
def test_the_pinned_tip_moves_the_audible_modes_up_a_few_per_cent(seed: int) -> None:
    """For any beam: every audible mode moves up, by about 1.5/n (3-16 % in 1.5-14 kHz), less as the order rises;
    the mode shapes are finite and of unit RMS (no cancelled hyperbolic terms)."""
    m = bm.beam_modes(bm.Beam(seed))
    g = np.asarray(m["stop_g"])
    both, i, j = np.intersect1d(m["step_n"], m["stop_n"], return_indices=True)  # mode n free against mode n pinned
    f, fp = np.asarray(m["step_f"])[i], np.asarray(m["stop_f"])[j]
    band = (f > 1500) & (f < 14000)
    rise = fp[band] / f[band] - 1
    assert np.allclose(rise, ((4 * both[band] + 1) / (4 * both[band] - 2)) ** 2 - 1, rtol=0.02)  # the asymptotes
    assert band.sum() >= 15 and np.all(rise > 0.025) and np.all(rise < 0.16), rise
    assert np.all(np.diff(rise) < 0)  # the shift falls with the order
    assert np.all(np.isfinite(g)) and np.max(np.abs(g)) < 5.0
    x = np.linspace(0, 1, 20001)
    b = bm.roots(True, 40)
    rms = np.sqrt(np.mean(bm.shapes(b, True, x) ** 2, axis=1))
    assert np.all(np.isfinite(rms)) and np.all((rms > 0.5) & (rms < 2.0))
    assert np.max(np.abs(bm.shapes(b, True, np.array([1.0])))) < 1e-6 * np.max(rms)  # pinned: w(L) = 0


def test_the_stop_keeps_the_energy_and_changes_only_the_spectrum() -> None:
    """Beam 1: the stop's RMS is within 1 dB of the stepping's, while its spectrum moves (the power in 1/12-octave
    sub-bands changes by more than 6 dB somewhere)."""
    from stickslip.audio.features.spectra import subband_edges, subband_levels_db

    y = np.asarray(bm.render(bm.tuning_scene(bm.Beam(1))), dtype=np.float64)
    a, b = y[SR // 2 : int(1.9 * SR)], y[int(2.1 * SR) :]
    assert abs(10 * np.log10(np.mean(b**2) / np.mean(a**2))) < 1.0
    e = subband_edges(1500.0, 14000.0, SR, 512, 12)
    d = np.median(subband_levels_db(b, SR, 512, 128, e), 0) - np.median(subband_levels_db(a, SR, 512, 128, e), 0)
    assert np.max(np.abs(d)) > 6.0


@cache
def _beam_tuning(beam: int) -> Tuning:
    return tune(bm.render(bm.tuning_scene(bm.Beam(beam))), SR, 2.0)


def _beam_draws(beam: int, n: int) -> list[bm.Scene]:
    """Recordings of the beam within the tuning's domain: rate 1000 Hz +-3 %, jitter 0.2-3 %, SNR 25-40 dB."""
    rng = np.random.default_rng(500 + beam)
    return [
        bm.Scene(
            beam=bm.Beam(beam),
            rate=1000 * (1 + float(rng.uniform(-0.03, 0.03))),
            stop_at=float(rng.uniform(1.5, 2.5)),
            dur=3.5,
            jitter=float(rng.uniform(0.002, 0.03)),
            snr_db=float(rng.uniform(25, 40)),
            seed=int(rng.integers(1, 10**6)),
        )  # fmt: skip
        for _ in range(n)
    ]


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    beam=st.integers(11, 10**6),
    stop_at=st.floats(1.6, 2.4),
    jitter=st.floats(0.002, 0.01),
    snr_db=st.floats(30.0, 40.0),
    seed=st.integers(1, 10**6),
)
@example(beam=17762, stop_at=2.0, jitter=0.0078125, snr_db=30.0, seed=1)  # flagged, +16 ms (a fresh draw)
def test_any_beam_at_its_tuning_rate_is_heard_on_time(
    beam: int, stop_at: float, jitter: float, snr_db: float, seed: int
) -> None:
    """Any beam, tuned on its clean recording and heard at the tuning's rate (1000 Hz, jitter 0.2-1 %, SNR 30-40 dB):
    the stop is heard, on time or flagged, never missed or silently wrong (measured: 30 of 30 random beams on time,
    margins 0.69-0.95, all at 3 per octave; with round 9a's climb check 29 on time and one flagged as a slow rise,
    +16 ms: beam 254877, and beam 17762, a fresh draw). Another rate is another matter: see the named beams below."""
    tu = tune(bm.render(bm.tuning_scene(bm.Beam(beam))), SR, 2.0)
    s = bm.Scene(beam=bm.Beam(beam), stop_at=stop_at, jitter=jitter, snr_db=snr_db, seed=seed)
    kind, onsets = _outcome(tu, bm.render(s), stop_at)
    assert kind in ("right", "flagged"), (beam, kind, onsets, tu.checks)


@pytest.mark.parametrize("beam", [2, 4, 5, 6, 7, 10])
def test_a_pinned_beam_is_heard(beam: int) -> None:
    """Beams whose pinned tip is heard on time in every recording (measured: 10 of 10 each; the same before this
    round, as 3 per octave is kept for all of them: margins 0.86-0.95). Six of the ten here. Round 11a's second
    fit flagged one of beam 2's six; since round 12b's predicted drops it is on time again."""
    tu = _beam_tuning(beam)
    assert tu.per_octave == TuneParams().default_per_octave
    c = _count(tu, _beam_draws(beam, 6), bm.render)
    assert c["right"] == 6, c


@pytest.mark.parametrize(
    ("beam", "measured"),
    [
        (3, "a template that separates by 0.49 (12 per octave: 0.55, not 0.2 more): 6 right, 4 missed of 10"),
        (8, "9 right, 1 missed of 10"),
        (9, "6 right, 4 missed of 10"),
    ],
)
def test_beams_3_8_and_9_are_missed_sometimes_never_wrong(beam: int, measured: str) -> None:
    """What is still missed (docs/audio-log.md, "A stop that only shifts the spectrum"): safe (a traverse times out),
    never silently wrong."""
    c = _count(_beam_tuning(beam), _beam_draws(beam, 10), bm.render)
    assert c["early"] == c["late"] == 0, (measured, c)
    assert c["right"] >= 5 and c["right"] + c["missed"] + c["flagged"] == 10, (measured, c)


def test_beam_1s_late_onset_is_flagged() -> None:
    """Found by the sixth generator (rate 1000 Hz +1.4 %, jitter 2.6 %): the onset is 32 ms after the pinning, and was
    unflagged before round 9a; its climb to the threshold is slow, and the event is now flagged ``onset_uncertain``. On
    the tuned signature alone: round 11a's second fit hears it on time (``tests/test_audio_rate_signature.py``)."""
    s = _beam_draws(1, 3)[2]
    assert s.stop_at is not None
    kind, onsets = _outcome(tuned_alone(_beam_tuning(1)), bm.render(s), s.stop_at)
    assert kind == "flagged" and 0.025 < onsets[0] < 0.04, (kind, onsets)
