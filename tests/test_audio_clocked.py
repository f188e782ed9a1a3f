"""The stop's signature on the step clock's lines (``stickslip.audio.confirm.clocked``).

A click train at the step rate has all its power on the rate's harmonic lines; the check
reads the change of that power per sub-band and fits the stop's signature to it. Built
from a click train and band masks, so the answers are known: the joint's own sound scaled
by the signature gives ``a_L`` = 1, noise added between the lines gives 0, a drop counts as
a rise does, and the cases with nothing to judge give no verdict.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.audio.confirm.clocked import (
    CLOCKED,
    ClockedCheck,
    ClockedParams,
    OnClock,
    lines_stop_likeness,
    locked_stop_likeness,
)
from stickslip.audio.features.lockin import demodulate, follow_clock, locked_powers

SR = 48_000
RATE = 1000.0
EDGES = (2500.0, 4500.0, 8500.0, 16500.0)  # no line on an edge: each line and its flanks in one sub-band


def _clicks(n: int, seed: int) -> np.ndarray:
    """Clicks every 48 samples (1000 Hz), their strength scattered by 10 %, and a little noise."""
    rng = np.random.default_rng(seed)
    x = np.zeros(n)
    x[::48] = 1.0 + 0.1 * rng.standard_normal(x[::48].size)
    return x + 1e-4 * rng.standard_normal(n)


def _band(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``x`` with only the frequencies in [lo, hi) kept (an FFT mask)."""
    X = np.fft.rfft(x)
    f = np.fft.rfftfreq(x.size, 1 / SR)
    return np.fft.irfft(np.where((f >= lo) & (f < hi), X, 0.0), x.size)


def _scaled(x: np.ndarray, gains_db: tuple[float, ...]) -> np.ndarray:
    """``x`` with each of EDGES' sub-bands scaled by its gain (dB), the rest left out."""
    return sum(
        (10 ** (g / 20) * _band(x, lo, hi) for g, lo, hi in zip(gains_db, EDGES[:-1], EDGES[1:], strict=True)),
        np.zeros(x.size),
    )


N = int(0.48 * SR)


def test_the_joints_own_sound_changed_by_the_signature_is_a_stop() -> None:
    sig = (0.0, 6.0, -4.0)
    before = _scaled(_clicks(N, 1), (0.0, 0.0, 0.0))
    after = _scaled(_clicks(N, 2), sig)
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, sig)
    assert used == 2  # the sub-band the stop moves by 0 dB is not judged
    assert a == pytest.approx(1.0, abs=0.05)


def test_half_the_signature_on_the_lines_is_half_a_stop() -> None:
    """The fit is linear in dB: the lines moved by half the signature give a_L = 1/2."""
    sig = (8.0, 8.0, -6.0)
    a, used = lines_stop_likeness(
        _scaled(_clicks(N, 3), (0.0, 0.0, 0.0)), _scaled(_clicks(N, 4), (4.0, 4.0, -3.0)), SR, RATE, EDGES, sig, sig
    )
    assert used == 3
    assert a == pytest.approx(0.5, abs=0.05)


def test_noise_added_between_the_lines_is_not_a_stop() -> None:
    """Noise that raises the rising sub-band by 6 dB (as the stop would) leaves the lines where they were."""
    sig = (0.0, 6.0, 0.0)
    rng = np.random.default_rng(5)
    joint = _scaled(_clicks(N, 6), (0.0, 0.0, 0.0))
    mid = _band(joint, EDGES[1], EDGES[2])
    noise = _band(rng.standard_normal(N), EDGES[1], EDGES[2])
    noise *= math.sqrt(3.0) * np.sqrt(np.mean(mid**2)) / np.sqrt(np.mean(noise**2))  # 3x the joint's power: +6 dB
    after = _scaled(_clicks(N, 7), (0.0, 0.0, 0.0)) + noise
    power_db = 10 * np.log10(np.mean(_band(after, EDGES[1], EDGES[2]) ** 2) / np.mean(mid**2))
    assert power_db == pytest.approx(6.0, abs=0.3)  # the level detector would see the stop's rise
    a, used = lines_stop_likeness(joint, after, SR, RATE, EDGES, sig, sig)
    assert used == 1
    assert abs(a) < 0.1


def test_nothing_to_judge_gives_no_verdict() -> None:
    x = _scaled(_clicks(N, 8), (0.0, 0.0, 0.0))
    small = (1.0, -2.0, 2.9)  # the stop moves no sub-band by 3 dB
    a, used = lines_stop_likeness(x, x, SR, RATE, EDGES, small, small)
    assert (math.isnan(a), used) == (True, 0)
    noise = np.random.default_rng(9).standard_normal(N)  # no lines before the fire
    a, used = lines_stop_likeness(noise, noise, SR, RATE, EDGES, (6.0, 6.0, 6.0), (6.0, 6.0, 6.0))
    assert (math.isnan(a), used) == (True, 0)


class _Tuning:
    """The fields of a template tuning the check reads."""

    method = "template"
    sample_rate = SR
    edges_hz = EDGES
    signature_db = (0.0, 6.0, -4.0)
    continuum_signature_db = (0.0, 5.0, -4.5)
    step_rate_hz = RATE
    frame = 1024
    fine_start_hz: float | None = None  # no fine continuum: no signature predicted at another rate
    fine_bin_hz: float | None = None
    fine_stepping_db: tuple[float, ...] | None = None
    fine_stopped_db: tuple[float, ...] | None = None


def test_the_check_judges_a_window_against_its_reference() -> None:
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    assert chk.enabled
    after = _scaled(_clicks(N, 11), (0.0, 6.0, -4.0))
    assert chk.judge(after) is None  # no reference yet
    chk.hear_before(_scaled(_clicks(int(0.1 * SR), 10), (0.0, 0.0, 0.0)), np.full(40, -0.5))
    assert chk.judge(after) is None  # under min_s of stepping heard before the fire
    stepping = _scaled(_clicks(N, 10), (0.0, 0.0, 0.0))
    chk.hear_before(stepping, np.r_[np.full(60, -0.6), np.full(60, 0.2), np.full(20, np.nan)])
    assert chk.ref_stoplike == pytest.approx(0.5)  # half its frames stop-like (NaN: learning, not counted)
    assert chk.judge(after) is not None
    chk.hear_before(stepping, np.r_[np.full(59, -0.6), np.full(61, 0.2)])
    assert chk.judge(after) is None  # mostly stop-like before the fire: a stop heard late, no stepping to compare
    chk.hear_before(stepping, np.full(120, -0.6))
    got = chk.judge(after)
    assert got is not None and got.bands == 2 and got.rate_hz == pytest.approx(RATE, rel=0.01)
    assert got.a == pytest.approx(1.0, abs=0.05) and chk.verdict(got)
    chk.reset(1.1 * RATE)  # told a rate 10 % from the tuning's: the signature on the lines is not known there
    assert chk.ref is None and chk.commanded_hz == 1.1 * RATE
    chk.ref = _scaled(_clicks(N, 10), (0.0, 0.0, 0.0))
    assert chk.judge(after) is None


def test_a_reference_stop_like_to_the_levels_is_replaced_by_the_stepping_kept() -> None:
    """Music that lifted the stop's sub-bands before the fire: judged against the stepping kept before it, not skipped.

    A stretch is kept only where at most ``kept_stoplike`` of its frames were stop-like, and taken where it ended no
    more than ``kept_age_s`` before the fire's own reference ended; a sound added between the lines then gives
    ``a_L`` near 0 (a veto), the stop's signature on the lines near 1; with ``kept_age_s`` 0, no verdict."""
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    stepping, stoplike = _scaled(_clicks(N, 20), (0.0, 0.0, 0.0)), np.full(120, 0.3)
    chk.keep(10 * N, stepping, np.r_[np.full(12, 0.2), np.full(108, -0.4)])  # 10 % stop-like: kept
    chk.keep(11 * N, _scaled(_clicks(N, 21), (0.0, 6.0, -4.0)), np.r_[np.full(13, 0.2), np.full(107, -0.4)])  # 11 %
    chk.keep(12 * N, stepping, np.r_[np.full(119, -0.4), math.nan])  # a frame not heard (learning): not kept
    end = 10 * N + int(20.0 * SR)  # the fire's own reference ended 20 s after the stepping kept (30 s allowed)
    chk.hear_before(_scaled(_clicks(N, 22), (0.0, 6.0, 0.0)), stoplike, end)
    assert chk.ref is not None and np.array_equal(chk.ref, stepping) and chk.ref_stoplike == 0.0
    rng = np.random.default_rng(23)
    noise = _band(rng.standard_normal(N), EDGES[1], EDGES[2]) * 3.0 * np.sqrt(np.mean(_band(stepping, 4500, 8500) ** 2))
    music = chk.judge(_scaled(_clicks(N, 24), (0.0, 0.0, 0.0)) + noise)
    assert music is not None and music.kept_s == pytest.approx(20.0)
    assert abs(music.a) < 0.1 and not chk.verdict(music)
    stop = chk.judge(_scaled(_clicks(N, 25), (0.0, 6.0, -4.0)))
    assert stop is not None and stop.a == pytest.approx(1.0, abs=0.05) and chk.verdict(stop)
    chk.hear_before(stepping, stoplike, 10 * N + int(30.5 * SR))  # kept 30.5 s before: too old, no verdict
    assert chk.judge(stop_after := _scaled(_clicks(N, 25), (0.0, 6.0, -4.0))) is None
    chk.hear_before(stepping, np.full(120, -0.4), end)  # its own reference was stepping: kept nothing taken
    own = chk.judge(stop_after)
    assert own is not None and math.isnan(own.kept_s)
    off = ClockedCheck(_Tuning(), ClockedParams(kept_age_s=0.0))  # type: ignore[arg-type]
    off.keep(10 * N, stepping, np.full(120, -0.4))
    off.hear_before(stepping, stoplike, end)
    assert off.kept == [] and off.judge(stop_after) is None  # nothing kept: a reference stop-like, no verdict


def test_a_longer_window_is_read_in_spans_and_the_median_kept() -> None:
    """A 2 s window (a fire soon after a rejected one) read in four spans: a change on the lines in one span only (a
    note on a line) gives the median of the four, near 0; the stop's signature in all four gives 1."""
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    chk.hear_before(_scaled(_clicks(N, 30), (0.0, 0.0, 0.0)), np.full(120, -0.4))
    steps = [_scaled(_clicks(N, 31 + k), (0.0, 0.0, 0.0)) for k in range(4)]
    one = chk.judge(np.concatenate([_scaled(_clicks(N, 35), (0.0, 6.0, -4.0)), *steps[1:]]))
    assert one is not None and abs(one.a) < 0.1 and not chk.verdict(one)
    stop = chk.judge(np.concatenate([_scaled(_clicks(N, 36 + k), (0.0, 6.0, -4.0)) for k in range(4)]))
    assert stop is not None and stop.a == pytest.approx(1.0, abs=0.05)
    first = ClockedCheck(_Tuning(), ClockedParams(window_pieces=1))  # type: ignore[arg-type]
    first.hear_before(_scaled(_clicks(N, 30), (0.0, 0.0, 0.0)), np.full(120, -0.4))
    got = first.judge(np.concatenate([_scaled(_clicks(N, 35), (0.0, 6.0, -4.0)), *steps[1:]]))
    assert got is not None and got.a == pytest.approx(1.0, abs=0.05)  # read on its first span only


def test_the_verdict_vetoes_only_a_change_off_the_clock() -> None:
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    assert chk.verdict(None) and chk.verdict(OnClock(math.nan, RATE, 0))
    assert chk.verdict(OnClock(CLOCKED.min_a, RATE, 1)) and not chk.verdict(OnClock(CLOCKED.min_a - 0.01, RATE, 1))
    strict = ClockedCheck(_Tuning(), ClockedParams(min_a=0.9))  # type: ignore[arg-type]
    assert not strict.verdict(OnClock(0.8, RATE, 2))


def test_too_little_of_the_signature_judged_gives_no_verdict() -> None:
    """Lines heard only where the stop moves little (9 of the signature's 153 dB^2): no verdict, not a veto."""
    rng = np.random.default_rng(12)
    sig = (3.0, 12.0, 0.0)
    low = _band(_clicks(N, 13), EDGES[0], EDGES[1])
    before = low + _band(rng.standard_normal(N), EDGES[1], EDGES[2])  # no lines where the stop rises 12 dB
    after = _band(_clicks(N, 14), EDGES[0], EDGES[1]) + _band(rng.standard_normal(N), EDGES[1], EDGES[2])
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, sig)
    assert used == 1 and math.isnan(a)
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, sig, ClockedParams(min_covered=0.05))
    assert used == 1 and abs(a) < 0.1  # judged on that one sub-band, where nothing changed


def test_a_stop_whose_tuned_change_was_off_the_lines_is_not_judged_there() -> None:
    """The tuning's continuum rose 14 dB more than its level where the stop rises (a stop that rattles out of step):
    the lines there say nothing about the stop; the other sub-band is under half the signature: no verdict."""
    sig = (0.0, 12.0, -4.0)
    before = _scaled(_clicks(N, 15), (0.0, 0.0, 0.0))
    after = _scaled(_clicks(N, 16), (0.0, 0.0, -4.0))  # the lines do not rise: the stop's rise is off them
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, (0.0, 26.0, -3.0))
    assert (math.isnan(a), used) == (True, 1)  # the drop judged alone: 16 of 160 dB^2, too little
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, (0.0, 14.0, -3.0))  # within 3 dB: judged
    assert used == 2 and a == pytest.approx(16.0 / 160.0, abs=0.05)  # only the drop's -4 dB of the signature


def _tones(n: int, freqs_hz: list[float], power: float, seed: int) -> np.ndarray:
    """Sines at ``freqs_hz``, each of mean square ``power``, random phases."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / SR
    return sum(
        (math.sqrt(2 * power) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in freqs_hz), np.zeros(n)
    )


def test_partials_beside_the_lines_are_read_on_the_narrow_comb() -> None:
    """Music's partials 35 Hz from each line where the stop rises: the 0.4 % comb's wider comb holds them (not sharp:
    no verdict), the comb as narrow as the window resolves does not, and reads no change: a_L near 0."""
    sig = (0.0, 12.0, 0.0)
    joint = _scaled(_clicks(N, 21), (0.0, 0.0, 0.0))
    mid = _band(joint, EDGES[1], EDGES[2])
    per_line = float(np.mean(mid**2)) / 4  # four lines, 5-8 kHz
    music = _tones(N, [k * RATE + 35.0 for k in (5, 6, 7, 8)], per_line, 22)
    before = joint + music
    after = _scaled(_clicks(N, 23), (0.0, 0.0, 0.0)) + music
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, sig, ClockedParams(combs=(0.004,)))
    assert (math.isnan(a), used) == (True, 0)
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, sig)
    assert used == 1 and abs(a) < 0.1
    a, used = lines_stop_likeness(before, _scaled(_clicks(N, 24), sig) + music, SR, RATE, EDGES, sig, sig)
    assert used == 1 and a == pytest.approx(1.0, abs=0.1)  # the stop itself, under the same partials


def _wandering_clicks(n: int, seed: int) -> np.ndarray:
    """Clicks at 1000 Hz whose rate wanders by +-0.2 % at 3 Hz (band-limited, at fractional sample times)."""
    rng = np.random.default_rng(seed)
    x = np.zeros(n + 64)
    t, k = 0.0, np.arange(-16, 17)
    while t * SR < n:
        i = int(t * SR)
        frac = t * SR - i
        x[i + 16 + k] += (1.0 + 0.1 * rng.standard_normal()) * np.sinc(k - frac) * np.hanning(35)[1:-1]
        t += (1.0 + 0.002 * math.sin(2 * math.pi * 3.0 * t)) / RATE
    return x[16 : n + 16] + 1e-4 * rng.standard_normal(n)


def test_lines_wider_than_the_narrow_comb_are_read_on_a_wider_one() -> None:
    """A clock that wanders 0.2 %: its lines at 5-8 kHz spread +-10-16 Hz, beyond the narrow comb (not sharp
    there) and within 0.4 % of their frequency: read there, the stop scaled by the signature gives a_L near 1."""
    sig = (0.0, 12.0, 0.0)
    before = _scaled(_wandering_clicks(N, 25), (0.0, 0.0, 0.0))
    after = _scaled(_wandering_clicks(N, 26), sig)
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, sig, ClockedParams(combs=(0.0,)))
    assert (math.isnan(a), used) == (True, 0)
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, sig)
    assert used == 1 and a == pytest.approx(1.0, abs=0.1)


# The lines read in phase with the steps' clock followed from the sound (``locked_frame_s``, ``.features.lockin``).
LOCKED = CLOCKED  # on by default


def _jumping_clicks(n: int, seed: int, jump_at: int) -> np.ndarray:
    """Clicks every 48 samples; from sample ``jump_at`` on, half a period (24 samples) later: a new burst."""
    x = _clicks(n, seed)
    x[jump_at:] = 0.0
    rng = np.random.default_rng(seed + 100)
    x[jump_at + 24 :: 48] = 1.0 + 0.1 * rng.standard_normal(x[jump_at + 24 :: 48].size)
    return x + 1e-4 * rng.standard_normal(n)


def test_the_clock_is_followed_through_a_wandering_rate_and_a_new_burst() -> None:
    """A clock wandering 0.2 % keeps its 7th line in phase with the clock followed (the commanded clock loses it);
    a burst restarting the phase half-way is re-acquired at once (followed slowly, half the stretch is lost)."""
    ks = list(range(1, 13))
    z = demodulate(_wandering_clicks(N, 31), SR, RATE, ks, 960)
    locked, whole = locked_powers(z, ks, follow_clock(z, ks, LOCKED.locked_slew, LOCKED.locked_reacquire))
    assert locked[6] / whole[6] > 0.9
    fixed, _ = locked_powers(z, ks, np.zeros(z.shape[0]))
    assert fixed[6] / whole[6] < 0.5
    z = demodulate(_jumping_clicks(N, 32, N // 2), SR, RATE, ks, 960)
    locked, whole = locked_powers(z, ks, follow_clock(z, ks, LOCKED.locked_slew, LOCKED.locked_reacquire))
    assert locked[6] / whole[6] > 0.9
    slow, _ = locked_powers(z, ks, follow_clock(z, ks, LOCKED.locked_slew, math.inf))
    assert slow[6] / whole[6] < 0.6


def test_in_phase_a_note_beside_a_line_is_not_a_stop_and_the_stop_is() -> None:
    """A note 0.2 % off the 6th line (in the sub-band the stop raises 12 dB), 14 dB over the line: the lines' power
    rises there (the comb reads a stop), their power in phase with the steps does not (a_L near 0); the joint's
    own sound scaled by the signature reads 1 both ways."""
    sig = (0.0, 12.0, 0.0)
    before = _scaled(_wandering_clicks(N, 33), (0.0, 0.0, 0.0))
    mid = _band(before, EDGES[1], EDGES[2])
    note = _tones(N, [6 * RATE * 1.002], 10**1.4 * float(np.mean(mid**2)) / 4, 34)
    after = _scaled(_wandering_clicks(N, 35), (0.0, 0.0, 0.0)) + note
    a, used = lines_stop_likeness(before, after, SR, RATE, EDGES, sig, sig)
    assert used == 1 and a > 0.5
    assert abs(locked_stop_likeness(before, [after], SR, RATE, EDGES, sig, sig, LOCKED)) < 0.15
    stop = _scaled(_wandering_clicks(N, 36), sig)
    assert locked_stop_likeness(before, [stop], SR, RATE, EDGES, sig, sig, LOCKED) == pytest.approx(1.0, abs=0.1)
    off = ClockedParams(locked_frame_s=0.0)
    assert math.isnan(locked_stop_likeness(before, [stop], SR, RATE, EDGES, sig, sig, off))  # off: not read


def test_in_phase_no_verdict_where_the_lines_were_not_locked_before() -> None:
    """Noise where the stop rises (no lines in phase before the fire): no verdict, not a veto."""
    sig = (0.0, 12.0, 0.0)
    rng = np.random.default_rng(37)
    before = _band(rng.standard_normal(N), EDGES[1], EDGES[2])
    after = _band(rng.standard_normal(N), EDGES[1], EDGES[2])
    assert math.isnan(locked_stop_likeness(before, [after], SR, RATE, EDGES, sig, sig, LOCKED))


def test_the_verdict_vetoes_a_change_out_of_phase_too() -> None:
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    assert not chk.verdict(OnClock(1.0, RATE, 2, math.nan, 0.1))  # on the comb a stop, in phase not
    assert not chk.verdict(OnClock(0.1, RATE, 2, math.nan, 1.0))
    assert chk.verdict(OnClock(math.nan, RATE, 0, math.nan, 0.9)) and chk.verdict(OnClock(0.9, RATE, 2))
    assert not chk.verdict(OnClock(math.nan, RATE, 0, math.nan, 0.1))  # the comb could not judge; in phase can


def test_only_both_readings_at_min_affirm_affirm_a_fire() -> None:
    """A fire the levels hold but not hot is a stop only where the comb and the lines in phase both read
    ``min_affirm`` or more: a reading missing (NaN), or one under it, does not affirm."""
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    m = CLOCKED.min_affirm
    assert chk.affirms(OnClock(m, RATE, 2, math.nan, m)) and chk.affirms(OnClock(1.0, RATE, 2, math.nan, 0.9))
    assert not chk.affirms(None)
    assert not chk.affirms(OnClock(1.0, RATE, 2))  # in phase not read
    assert not chk.affirms(OnClock(math.nan, RATE, 0, math.nan, 1.0))  # the comb could not judge
    assert not chk.affirms(OnClock(m - 0.01, RATE, 2, math.nan, 1.0))
    assert not chk.affirms(OnClock(1.0, RATE, 2, math.nan, m - 0.01))
    assert chk.verdict(OnClock(0.3, RATE, 2, math.nan, 0.3))  # not vetoed, yet not affirmed either
    assert not chk.affirms(OnClock(0.3, RATE, 2, math.nan, 0.3))


def test_the_lines_read_in_phase_from_an_onset_tell_the_stop_from_stepping() -> None:
    """From a stop's onset on, the joint's own sound scaled by the signature reads 1 in phase; stepping (the fire
    came before the stop) reads near 0; too little read, or no fire judged, gives NaN."""
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    stepping = _scaled(_clicks(N, 40), (0.0, 0.0, 0.0))
    chk.hear_before(stepping, np.full(120, -0.6))
    got = chk.judge(_scaled(_clicks(N, 41), (0.0, 6.0, -4.0)))
    assert got is not None
    n = int(round(CLOCKED.onset_read_s * SR))
    assert chk.at_onset(_scaled(_clicks(n, 42), (0.0, 6.0, -4.0)), got) == pytest.approx(1.0, abs=0.1)
    assert abs(chk.at_onset(_scaled(_clicks(n, 43), (0.0, 0.0, 0.0)), got)) < 0.1
    assert math.isnan(chk.at_onset(_scaled(_clicks(n - 1, 42), (0.0, 6.0, -4.0)), got))  # under onset_read_s
    assert math.isnan(chk.at_onset(_scaled(_clicks(n, 42), (0.0, 6.0, -4.0)), None))
    rough = OnClock(math.nan, got.rate_hz, 0, math.nan, got.locked)  # the comb could not judge the fire: not read
    assert math.isnan(chk.at_onset(_scaled(_clicks(n, 43), (0.0, 0.0, 0.0)), rough))


def test_at_another_rate_the_lines_may_affirm_a_stop_and_veto_only_lines_that_did_not_move() -> None:
    """Told a rate 10 % from the tuning's, the tuned signature is not what the stop does on the lines: a reading
    under ``min_a`` is no veto there, but read for an affirmation the joint's clicks changed by the signature still
    read a_L near 1 and affirm. What vetoes there is the lines in phase not moving at all (``min_moved_db``): the
    stop's window moved them by the signature's RMS (4.2 dB over its three sub-bands), the
    same window with its change undone by about 0 dB, and that is no stop (nor is an onset read); with
    ``min_moved_db`` 0 nothing is read for a veto (the check as it was); within 1 % of the tuning's rate the reading
    under ``min_a`` is a veto. Beyond ``affirm_window``, or untold, nothing is read."""
    fast = 1.1 * RATE
    step = round(SR / fast)  # a click every 44 samples: 1090.9 Hz, 9 % from the tuning's rate

    def clicks(n: int, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        x = np.zeros(n)
        x[::step] = 1.0 + 0.1 * rng.standard_normal(x[::step].size)
        return x + 1e-4 * rng.standard_normal(n)

    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    chk.reset(SR / step)
    chk.hear_before(_scaled(clicks(N, 10), (0.0, 0.0, 0.0)), np.full(120, -0.6))
    stop, none = _scaled(clicks(N, 11), (0.0, 6.0, -4.0)), _scaled(clicks(N, 11), (0.0, 0.0, 0.0))
    moved, still = chk.judge(stop), chk.judge(none)
    assert moved is not None and still is not None and not chk.at_tuned_rate(moved.rate_hz)
    assert moved.moved_db == pytest.approx(math.sqrt((36.0 + 16.0) / 3.0), abs=0.5) and chk.verdict(moved)
    assert still.moved_db < 0.3 and not chk.verdict(still)  # the lines did not move: the stepping went on
    assert math.isnan(chk.at_onset(none, still))  # at another rate: no onset doubt
    old = ClockedCheck(_Tuning(), ClockedParams(min_moved_db=0.0))  # type: ignore[arg-type]
    old.reset(SR / step)
    old.hear_before(_scaled(clicks(N, 10), (0.0, 0.0, 0.0)), np.full(120, -0.6))
    assert old.judge(stop) is None and old.judge(none) is None  # no verdict for a veto at this rate
    got = chk.judge(stop, affirm=True)
    assert got is not None and got.rate_hz == pytest.approx(SR / step, rel=0.01)
    assert got.a == pytest.approx(1.0, abs=0.1) and got.locked == pytest.approx(1.0, abs=0.1) and chk.affirms(got)
    nothing = chk.judge(none, affirm=True)
    assert nothing is not None and abs(nothing.a) < 0.1 and not chk.affirms(nothing)
    unmoved = OnClock(nothing.a, nothing.rate_hz, 2, math.nan, nothing.locked)  # moved not read
    assert chk.verdict(unmoved)  # a reading under min_a at another rate: no veto
    assert not chk.verdict(OnClock(nothing.a, RATE, 2, math.nan, nothing.locked))  # at the tuning's rate: a veto
    stepping = _scaled(clicks(N, 10), (0.0, 0.0, 0.0))
    for p, told, read in ((CLOCKED, SR / step, True), (CLOCKED, None, False),
                          (ClockedParams(affirm_window=0.05), SR / step, False)):  # fmt: skip
        other = ClockedCheck(_Tuning(), p)  # type: ignore[arg-type]
        other.reset(told)
        other.hear_before(stepping, np.full(120, -0.6))
        assert (other.judge(stop, SR / step, affirm=True) is not None) is read  # 9 % off: within 25 %, not 5 %



class _Predicting(_Tuning):
    """A tuning whose stop the comb cannot judge at 1091 Hz but whose fine continuum says it moves the lines there.

    The tuned stop rises in a fourth sub-band (16.5-20 kHz) where the stepping below holds no line: no comb verdict.
    The stopped fine continuum is 10 dB over the stepping's at 3.20-3.35 kHz, between the tuning's lines (3 and 4 kHz)
    and on the third line at 1091 Hz (3273 Hz): predicted there, the stop raises the first sub-band's two lines by
    10 log10((10 + 1) / 2) = 7.4 dB and the others not, sqrt(7.4^2 / 3) = 4.3 dB RMS over the three locked."""

    edges_hz = (*EDGES, 20000.0)
    signature_db = (0.0, 0.0, 0.0, 6.0)
    continuum_signature_db = (0.0, 0.0, 0.0, 6.0)
    fine_start_hz = 2000.0
    fine_bin_hz = 5.0
    fine_stepping_db = (0.0,) * 4000
    fine_stopped_db = tuple(10.0 if 3200.0 <= 2000.0 + 5.0 * i < 3350.0 else 0.0 for i in range(4000))


def test_at_another_rate_unjudged_by_the_comb_the_prediction_says_whether_unmoved_lines_veto() -> None:
    """Told 1091 Hz (9 % off), the comb gives no verdict (no line in the tuned stop's sub-band); where the signature
    predicted at the rate moves the locked lines ``min_pred_moved_db`` or more (4.3 dB RMS here), lines that did not
    move (noise added between them) are no stop, and lines raised by 6 dB are one; with the parameter 0 (the check
    as it was), with a fine continuum that predicts no move, or with none, nothing is read for a veto."""
    step = 44  # a click every 44 samples: 1090.9 Hz
    rate = SR / step

    def joint(seed: int) -> np.ndarray:  # the clicks up to 16.5 kHz, over a broadband hiss
        rng = np.random.default_rng(seed)
        x = np.zeros(N)
        x[::step] = 1.0 + 0.1 * rng.standard_normal(x[::step].size)
        return _band(x, EDGES[0], EDGES[-1]) + 1e-4 * rng.standard_normal(N)

    def check(p: ClockedParams, tuning: _Tuning) -> ClockedCheck:
        chk = ClockedCheck(tuning, p)  # type: ignore[arg-type]
        chk.reset(rate)
        chk.hear_before(joint(10), np.full(120, -0.6))
        return chk

    stepping = joint(11)
    added = stepping + _band(0.05 * np.random.default_rng(3).standard_normal(N), EDGES[0], 20000.0)  # out of step
    stop = 10 ** (6.0 / 20) * stepping
    chk = check(ClockedParams(min_pred_moved_db=2.5), _Predicting())
    assert chk.predicted_moved_db(rate) == pytest.approx(math.sqrt((10 * math.log10(11 / 2)) ** 2 / 3), abs=0.3)
    still, moved = chk.judge(added), chk.judge(stop)
    assert still is not None and moved is not None and math.isnan(still.a) and math.isnan(moved.a)
    assert still.moved_db < 0.5 and not chk.verdict(still)  # the lines did not move: the stepping went on
    assert moved.moved_db == pytest.approx(6.0, abs=0.5) and chk.verdict(moved)
    assert math.isnan(chk.at_onset(stop, moved)) and not chk.affirms(moved)  # no comb verdict: no doubt, no affirm
    assert check(ClockedParams(min_pred_moved_db=0.0), _Predicting()).judge(added) is None  # the check as it was
    flat = _Predicting()
    flat.fine_stopped_db = flat.fine_stepping_db  # the stop predicted to move nothing on these lines at this rate
    assert check(ClockedParams(min_pred_moved_db=2.5), flat).predicted_moved_db(rate) < 0.1
    assert check(ClockedParams(min_pred_moved_db=2.5), flat).judge(added) is None
    old = _Predicting()
    old.fine_stopped_db = None  # a tuning made before the fine continuum was kept
    assert math.isnan(check(ClockedParams(min_pred_moved_db=2.5), old).predicted_moved_db(rate))
    assert check(ClockedParams(min_pred_moved_db=2.5), old).judge(added) is None
