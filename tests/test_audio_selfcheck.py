"""The tuner's self-check with a sound shaped like the stop's own rise, and the candidate choice it informs.

A stop that only *adds* sound in some sub-bands looks, in a level spectrum, like anything
else that adds sound there: a voice, a tap, a whistle, another instrument. A stop that
also *lowers* other sub-bands does not: no added sound lowers a sub-band, and the
detector checks those drops. So among the candidate templates, ``tune`` prefers one a
sound shaped like the stop's rise does not fire, and names a chosen one that it does.

The arms here come from a fifth generator (``shaped_sound``: steps as noise bursts shaped
in the frequency domain), not the simulator's; the interference in the test recordings is
a whistle (a tone with vibrato), not the self-check's shaped noise.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from modal_sound import Scene as ModalScene
from modal_sound import render as modal_render
from scipy.signal import welch
from shaped_sound import Arm, render

from stickslip.audio.confirm import CONFIRM_S
from stickslip.audio.detector import detect
from stickslip.audio.tuning import tune
from stickslip.audio.tuning.inject import bursts, shaped_noise
from stickslip.audio.tuningfile import Tuning

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 48_000


def _drops_in_spreads(signature_db: tuple[float, ...], spread_db: tuple[float, ...]) -> float:
    """How much the stop lowers, RMS-summed over sub-bands in units of the stepping's spread, each capped at 3."""
    d = np.minimum(np.asarray(signature_db), 0.0) / np.asarray(spread_db)
    return float(np.sqrt(np.sum(np.maximum(d, -3.0) ** 2)))


def _checks(tu: Tuning) -> dict[str, Any]:
    assert tu.checks is not None
    return tu.checks


def _one_stop_on_time(x: np.ndarray, tuning: Tuning, stop_s: float) -> list[tuple[float, float]]:
    events = detect(x, tuning)
    got = [(round(e.onset_s, 3), round(e.detected_at_s, 3)) for e in events]
    assert len(events) == 1, f"stop at {stop_s} s; events (onset, detected) {got}"
    assert abs(events[0].onset_s - stop_s) <= 0.025, got
    return got


# arms whose stop rings a contact mode (+12 dB around 3 kHz) and damps the high modes (-8 dB above 6 kHz), the
# damping coming and going (in this share of the stop it is only weak_drop_db): their best-separating sub-ranges
# are the rise alone, and the tuner as merged in round 5 chose one (a whistle at 3 kHz then fired it)
ARMS = [
    pytest.param(Arm(weak_drop_share=0.5, weak_drop_db=-2.0, seed=1), id="damping weak half the time"),
    pytest.param(Arm(weak_drop_share=0.35, weak_drop_db=-2.0, seed=2), id="damping weak a third of the time"),
    pytest.param(Arm(weak_drop_share=0.5, weak_drop_db=0.0, seed=1), id="damping gone half the time"),
]


@pytest.mark.parametrize("arm", ARMS)
def test_a_stop_that_adds_and_lowers_is_not_tuned_on_its_rises_alone(arm: Arm) -> None:
    tu = tune(render(arm), SR, 2.0)
    assert tu.signature_db is not None and tu.spread_db is not None
    # the chosen template holds sub-bands the stop lowers, by more than the stepping's own wobble
    assert _drops_in_spreads(tu.signature_db, tu.spread_db) >= 2.0, (tu.edges_hz, tu.signature_db, tu.spread_db)
    # a whistle where the stop's contact mode rings, as loud as the ring and half as loud, fires nothing
    for seed, stop, kw in (
        (11, 2.2, {}),
        (12, 2.4, {"whistle_db": 12.0}),
        (13, 2.1, {"whistle_db": 6.0, "whistle_at": (0.7, 1.3)}),
    ):
        _one_stop_on_time(render(replace(arm, seed=seed, stop_at=stop, dur=stop + 0.7, **kw)), tu, stop)


@settings(max_examples=6, deadline=None)
@given(
    rise_hz=st.floats(1500.0, 5000.0),
    rise_db=st.floats(8.0, 15.0),
    drop_from_hz=st.floats(5500.0, 9000.0),
    drop_db=st.floats(-12.0, -6.0),
    seed=st.integers(1, 2**30),
)
def test_any_steady_stop_that_adds_and_lowers_is_tuned_to_check_its_drops(
    rise_hz: float, rise_db: float, drop_from_hz: float, drop_db: float, seed: int
) -> None:
    """Arms drawn at random (a steady stop: the damping does not come and go): a template that checks the drops,
    and the stop heard as ``listen`` hears it (confirmed): once, on time, or flagged ``onset_uncertain`` (a traverse
    refuses it), never silently early or late.

    Not asserted: that a whistle as loud as the ring never fires it. In 1 of 40 such arms
    drawn offline it did (round 6): the whistle gives half the stop's likeness, and the
    stepping's own wobble in the lowered sub-bands meets the drops asked of half a stop.
    Nor that the unconfirmed detector fires only at the stop: at the space's weakest corner
    (a rise of 8 dB, a drop of 6 dB from 5.5 or 8.4 kHz; two fresh draws, seeds 1 and 218) the
    stepping's wobble fired it 0.14-0.22 s before the stop, running into it; confirmed, both
    are flagged (pinned below).
    """
    arm = Arm(rise_hz=rise_hz, rise_db=rise_db, drop_from_hz=drop_from_hz, drop_db=drop_db, seed=seed)
    tu = tune(render(arm), SR, 2.0)
    assert tu.signature_db is not None and tu.spread_db is not None
    assert _drops_in_spreads(tu.signature_db, tu.spread_db) >= 2.0, (tu.edges_hz, tu.signature_db, tu.spread_db)
    events = detect(render(replace(arm, seed=seed + 11, stop_at=2.2, dur=2.9)), tu, confirm_s=CONFIRM_S)
    got = [(round(e.onset_s, 3), e.onset_uncertain) for e in events]
    assert len(events) == 1, got
    assert events[0].onset_uncertain or abs(events[0].onset_s - 2.2) <= 0.025, got


@pytest.mark.parametrize("drop_from_hz, seed", [(8430.0, 218), (5500.0, 1)])
def test_the_weakest_steady_stops_fire_early_unconfirmed_and_are_flagged_confirmed(
    drop_from_hz: float, seed: int
) -> None:
    """The two fresh draws at the property's weakest corner: the unconfirmed detector fires early (as found), the
    confirmed one flags the event, so a traverse refuses it rather than count to an early onset."""
    arm = Arm(rise_hz=1500.0, rise_db=8.0, drop_from_hz=drop_from_hz, drop_db=-6.0, seed=seed)
    tu = tune(render(arm), SR, 2.0)
    x = render(replace(arm, seed=seed + 11, stop_at=2.2, dur=2.9))
    raw = detect(x, tu)
    assert raw and raw[-1].onset_s < 2.2 - 0.1, [e.onset_s for e in raw]
    confirmed = detect(x, tu, confirm_s=CONFIRM_S)
    assert len(confirmed) == 1 and confirmed[0].onset_uncertain, [(e.onset_s, e.onset_uncertain) for e in confirmed]


def test_the_self_check_names_a_stop_that_only_adds_sound() -> None:
    """A rise-only stop: every candidate is fired by the shaped sound; the tuning says so, and still tunes."""
    arm = Arm(drop_db=0.0, seed=3)
    tu = tune(render(arm), SR, 2.0)
    assert _checks(tu)["rise_mimic"]["+0 dB"] >= 1
    assert any("lowers nothing" in w for w in _checks(tu)["warnings"]), _checks(tu)["warnings"]
    # it still finds the stop in a quiet room
    _one_stop_on_time(render(replace(arm, seed=21, stop_at=2.3, dur=3.0)), tu, 2.3)
    # the same arm whose stop also damps the high modes: nothing fires, nothing to warn about
    both = tune(render(replace(arm, drop_db=-8.0)), SR, 2.0)
    assert sum(_checks(both)["rise_mimic"].values()) == 0
    assert not any("lowers nothing" in w for w in _checks(both)["warnings"])


def test_the_fourth_generators_rise_only_arm_is_named() -> None:
    """Arm 3's spectral stop (``modal_sound``) lowers nothing worth checking in any sub-range: the warning says so."""
    tu = tune(modal_render(ModalScene(3, "spectral", stop_at=3.0, dur=4.5, seed=10)), SR, 3.0)
    assert tu.signature_db is not None and tu.spread_db is not None
    assert _drops_in_spreads(tu.signature_db, tu.spread_db) < 2.0
    assert sum(_checks(tu)["rise_mimic"].values()) == 3
    assert any("lowers nothing" in w for w in _checks(tu)["warnings"])


def test_no_mimicry_measured_when_the_stepping_part_cannot_hold_a_burst() -> None:
    """0.3 s of stepping before the stop: no room after the warm-up; the check says nothing rather than guess."""
    arm = Arm(stop_at=0.45, dur=1.4, drop_db=0.0, seed=4)
    tu = tune(render(arm), SR, 0.45)
    assert _checks(tu)["rise_mimic"] == {}


@settings(max_examples=25, deadline=None)
@given(
    lo=st.floats(400.0, 4000.0),
    widths=st.lists(st.floats(0.15, 0.8), min_size=1, max_size=6),
    levels=st.lists(st.floats(-70.0, -20.0), min_size=6, max_size=6),
    seed=st.integers(0, 2**31 - 1),
)
def test_shaped_noise_has_the_power_asked_in_each_band(
    lo: float, widths: list[float], levels: list[float], seed: int
) -> None:
    """Measured independently (Welch's periodogram, integrated over each band), nothing outside.

    Within four standard errors of the estimate: a band B Hz wide measured over T s holds
    about B T independent values, so its power is known to 1/sqrt(B T) (4.3/sqrt(B T) dB);
    a flat 0.5 dB failed at random on bands 200 Hz wide (hypothesis found one).
    """
    edges = [lo]
    for w in widths:
        edges.append(edges[-1] * 2**w)
    edges = [e for e in edges if e < 0.45 * SR]
    if len(edges) < 2:
        return
    ms = 10 ** (np.asarray(levels[: len(edges) - 1]) / 10)
    dur = 4.0
    y = shaped_noise(int(dur * SR), SR, edges, ms, np.random.default_rng(seed))
    # Blackman-Harris: its sidelobes (-92 dB) keep a band 50 dB louder next door out of the estimate
    f, p = welch(y, SR, window="blackmanharris", nperseg=8192, scaling="density")
    df = f[1] - f[0]
    for b in range(len(edges) - 1):
        inner = (f >= edges[b] + 5 * df) & (f < edges[b + 1] - 5 * df)  # clear of the window's main lobe
        if inner.sum() < 8:
            continue
        got = float(np.sum(p[inner]) * df) * (edges[b + 1] - edges[b]) / (inner.sum() * df)
        tol = 0.2 + 4 * 4.34 / np.sqrt(inner.sum() * df * dur)
        assert 10 * np.log10(got / ms[b]) == pytest.approx(0.0, abs=tol), (b, edges)
    outside = (f < edges[0] - 200) | (f > edges[-1] + 200)
    assert float(np.sum(p[outside]) * df) < 1e-3 * float(np.sum(ms))


def test_bursts_are_one_inside_zero_outside_with_ramps() -> None:
    env = bursts(SR, SR, [(0.1, 0.06), (0.5, 0.3), (0.95, 0.005)])
    t = np.arange(SR) / SR
    assert np.all(env[(t > 0.106) & (t < 0.154)] == 1.0) and np.all(env[(t > 0.506) & (t < 0.794)] == 1.0)
    assert np.all(env[(t < 0.1) | ((t > 0.16) & (t < 0.5)) | (t >= 0.8)] == 0.0)  # the 5 ms burst is too short
    ramp = env[int(0.1 * SR) : int(0.105 * SR)]
    assert np.all(np.diff(ramp) > 0) and 0.0 <= ramp[0] < 0.01
