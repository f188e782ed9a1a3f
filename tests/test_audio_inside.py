"""A stop that began inside a rejected fire's window, found on the joint's clock (``stickslip.audio.confirm.inside``).

Built from click trains and band masks (as ``test_audio_clocked.py``), so the answers are
known: the joint's clicks at 1000 Hz, scaled by the tuned signature from a known sample on,
with another instrument's clicks at 730 Hz in bursts as loud as the joint's. The stop is
found within a few milliseconds of where it was put, whatever the other clock does; no stop,
a stop too short to tell from a note, or a window that was the stop throughout (no
stepping in it: the fire was the stop) give None.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stickslip.audio.confirm.clocked import CLOCKED, ClockedCheck
from stickslip.audio.confirm.inside import INSIDE, onset_in_phase, stop_inside

SR = 48_000
RATE = 1000.0
EDGES = (2500.0, 4500.0, 8500.0, 16500.0)
SIG = (0.0, 6.0, -4.0)


class _Tuning:
    """The fields of a template tuning the check reads."""

    method = "template"
    sample_rate = SR
    edges_hz = EDGES
    signature_db = SIG
    continuum_signature_db = (0.0, 5.0, -4.5)
    step_rate_hz = RATE


def _clicks(n: int, period: float, seed: int) -> np.ndarray:
    """Clicks every ``period`` samples (rounded), their strength scattered by 10 %."""
    rng = np.random.default_rng(seed)
    x = np.zeros(n)
    at = np.round(np.arange(0.0, n, period)).astype(int)
    at = at[at < n]
    x[at] = 1.0 + 0.1 * rng.standard_normal(at.size)
    return x


def _scaled(x: np.ndarray, gains_db: tuple[float, ...]) -> np.ndarray:
    X = np.fft.rfft(x)
    f = np.fft.rfftfreq(x.size, 1 / SR)
    g = np.zeros(f.size)
    for gain, lo, hi in zip(gains_db, EDGES[:-1], EDGES[1:], strict=True):
        g[(f >= lo) & (f < hi)] = 10 ** (gain / 20)
    return np.fft.irfft(X * g, x.size)


def _joint(n: int, stop_at: int | None, seed: int) -> np.ndarray:
    """The joint stepping at 1000 Hz; from ``stop_at`` on (None: never) its sound scaled by the signature."""
    x = _scaled(_clicks(n, SR / RATE, seed), (0.0, 0.0, 0.0))
    if stop_at is not None:
        x[stop_at:] = _scaled(_clicks(n, SR / RATE, seed + 1), SIG)[stop_at:]
    return x + 1e-4 * np.random.default_rng(seed + 2).standard_normal(n)


def _bursts(n: int, spans: list[tuple[float, float]], seed: int) -> np.ndarray:
    """Another instrument at 730 Hz, on over ``spans`` (s), as loud as the joint."""
    x = _scaled(_clicks(n, SR / 730.0, seed), (0.0, 0.0, 0.0))
    on = np.zeros(n, dtype=bool)
    for a, b in spans:
        on[int(a * SR) : int(b * SR)] = True
    return np.where(on, x, 0.0)


def _check(seed: int) -> ClockedCheck:
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    chk.reset(RATE)  # the rate the traverse commands
    chk.hear_before(_joint(int(0.48 * SR), None, seed), np.full(120, -0.6))
    return chk


LEAD = int(round(INSIDE.piece_s * SR))
N = LEAD + int(1.5 * SR)  # the lead and a window of 1.5 s


@pytest.mark.parametrize(("stop_s", "spans"), [(0.83, []), (0.6, [(0.3, 0.7)]), (0.95, [(0.0, 0.5), (0.9, 1.6)])])
def test_a_stop_inside_the_window_is_found_whatever_the_other_clock_does(
    stop_s: float, spans: list[tuple[float, float]]
) -> None:
    """The onset within 5 ms of the stop (the other instrument starting before it, or after), both readings at 1."""
    at = LEAD + int(stop_s * SR)
    x = _joint(N, at, 5) + _bursts(N, [(a + LEAD / SR, b + LEAD / SR) for a, b in spans], 6)
    got = stop_inside(x, LEAD, _check(7), RATE)
    assert got is not None
    assert abs(got.onset - at) <= 0.005 * SR
    assert got.spread <= INSIDE.max_onset_off_s * SR  # pinned: not flagged
    assert got.on_clock.a == pytest.approx(1.0, abs=0.15) and got.on_clock.locked == pytest.approx(1.0, abs=0.15)


def test_no_stop_a_short_one_or_a_window_that_was_the_stop_throughout_give_none() -> None:
    chk = _check(8)
    other = _bursts(N, [(0.2, 0.9), (1.2, 1.6)], 9)
    assert stop_inside(_joint(N, None, 10) + other, LEAD, chk, RATE) is None  # the other instrument alone
    for left_s in (0.12, 0.4):  # under min_run_s of the stop at the window's end: a note on a line could do that
        assert stop_inside(_joint(N, N - int(left_s * SR), 11), LEAD, chk, RATE) is None
    assert stop_inside(_joint(N, LEAD // 2, 12), LEAD, chk, RATE) is None  # no stepping inside the window
    assert stop_inside(_joint(N, LEAD + SR // 2, 13), LEAD // 2, chk, RATE) is None  # a lead shorter than a piece


def test_no_verdict_without_a_reference_or_at_a_rate_the_tuning_does_not_know() -> None:
    x = _joint(N, LEAD + SR // 2, 14)
    chk = ClockedCheck(_Tuning())  # type: ignore[arg-type]
    assert stop_inside(x, LEAD, chk, RATE) is None  # no stepping heard before the fire
    chk = _check(15)
    chk.reset(1.1 * RATE)
    chk.hear_before(_joint(int(0.48 * SR), None, 15), np.full(120, -0.6))
    assert stop_inside(x, LEAD, chk, math.nan) is None  # told 10 % off the tuning's rate: the signature not known


@pytest.mark.parametrize("gains_db", [(0.0, 28.0, 0.0), (0.0, 0.0, -12.0), (0.0, 6.0, -4.0)])
def test_the_lines_change_is_placed_where_it_is_whichever_way_the_stop_moves_them(gains_db: tuple[float, ...]) -> None:
    """A stop that raises one sub-band 28 dB (a stretch a fifth stopped already reads as the stop in dB), one that
    lowers one 12 dB (read as the stop only once mostly stopped), and a mixed one: placed within 5 ms, pinned, with
    the other instrument stepping in and out across the stop (its lines turn against the joint's clock)."""
    n, at = int(0.4 * SR), int(0.23 * SR)
    x = _scaled(_clicks(n, SR / RATE, 20), (0.0, 0.0, 0.0))
    x[at:] = _scaled(_clicks(n, SR / RATE, 21), gains_db)[at:]
    x = x + _bursts(n, [(0.16, 0.4)], 22) + 1e-4 * np.random.default_rng(23).standard_normal(n)
    t, spread = onset_in_phase(x, SR, RATE, list(range(3, 17)), CLOCKED)
    assert abs(t - at) <= 0.005 * SR and spread <= INSIDE.max_onset_off_s * SR
    t, spread = onset_in_phase(x[: int(0.06 * SR)], SR, RATE, [3, 4], CLOCKED)  # three frames: not fitted
    assert (t, spread) == (-1, int(0.06 * SR))
