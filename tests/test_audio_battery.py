"""The battery: ~40 named conditions from a third, independent generator (tests/support/battery_sound.py).

Each condition tunes on a training recording and listens (as ``listen`` does: every fire
confirmed by its persistence, stickslip.audio.confirm) to a test recording it has not
heard (another seed, and the condition's interference, gain, rate, rate of sampling or
channel count). A condition passes when the stop is found once with its onset within
25 ms and no false alarm, or, where refusing is right (nothing to learn, a label where
nothing changes, a dead input), when ``tune`` refuses or ``listen`` hears nothing. The
latency targets (median <= 30 ms, 95th percentile <= 50 ms) are checked over all the
conditions that find a stop.

Conditions come in three groups: ``core`` (the issue's list), ``cross`` (the test's stop
departs from stepping in another direction than the training's: louder against quieter,
duller against brighter, level against spectral) and ``hostile`` (written before the
detector was changed for them: a stop that fades in, a drifting step clock, 8-bit audio,
22.05 kHz, a recording that starts at the stop). A stop without a sharp onset (a fade,
or a recording that starts at the stop) passes with an onset up to ``late_s`` late.

Each test recording is heard with the late path on (``listen --late``, round 12a): a stop the
fast path misses and the late path finds 0.5-0.75 s later, with its onset right, is printed
``late`` and still fails (the latency criterion is not loosened; the latency targets are
the fast path's). With the late path off those conditions give no event at all.

Run ``python tests/test_audio_battery.py`` for the table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from battery_sound import Scene, espeak_speech, render, variant  # noqa: E402
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)  # noqa: E402

from stickslip.audio.confirm import CONFIRM_S  # noqa: E402
from stickslip.audio.detector import detect  # noqa: E402
from stickslip.audio.tuning import TuningError  # noqa: E402

# make test-fast leaves this file out; make test (--dist loadgroup) runs it on one worker, so the latency test reads
# the outcomes the conditions' tests cached instead of hearing half the battery again
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("audio_battery")]

TOL_S = 0.025


@dataclass(frozen=True)
class Condition:
    name: str
    train: Scene
    test: Scene
    label_s: float | None = None  # the training label, if not the true stop
    expect: str = "found"  # "found", "refused" (tune must refuse), "silent" (listen hears nothing)
    warn: bool = False  # tune must warn that the label disagrees with the sound
    known_failure: str | None = None  # why this condition is expected to fail today (strict xfail)
    lead_s: float = 0.0  # seconds of room sound (no stepping) before the test recording
    late_s: float = 0.0  # the stop has no sharp onset: the onset may be this much late, the latency too
    group: str = "core"  # "core", "cross" (trained on one kind of stop, tested on another), "hostile"


P = Scene("P", 1000.0, 2.0, 3.0, seed=1)
Q = Scene("Q", 1000.0, 2.0, 3.0, seed=2)


def _test(s: Scene, seed: int, stop_at: float = 1.6, **kw: object) -> Scene:
    return variant(s, seed=seed, stop_at=stop_at, dur=stop_at + 0.6, rate=kw.pop("rate", 1080.0), **kw)


CONDITIONS = [
    Condition("clean joint P", P, _test(P, 11)),
    Condition("clean joint Q", Q, _test(Q, 12)),
    Condition("SNR 20 dB white noise", P, _test(P, 13, snr_db=20.0)),
    Condition("SNR 10 dB white noise", Q, _test(Q, 14, snr_db=10.0)),
    Condition("gain +20 dB", P, _test(P, 15, gain_db=20.0)),
    Condition("gain -20 dB", Q, _test(Q, 16, gain_db=-20.0)),
    Condition("step rate 700 Hz", P, _test(P, 17, rate=700.0)),
    Condition("step rate 1400 Hz", Q, _test(Q, 18, rate=1400.0)),
    Condition("knocks in test", P, _test(P, 19, knocks_every_s=0.25)),
    Condition("knocks in test, joint Q", Q, _test(Q, 20, knocks_every_s=0.3)),
    Condition("knocks in training", variant(P, knocks_every_s=0.4), _test(P, 21)),
    Condition("speech (espeak-ng) in test", P, _test(P, 22, speech="espeak")),
    Condition("speech (espeak-ng) in training", variant(Q, speech="espeak"), _test(Q, 23)),
    Condition(
        "loud speech (espeak-ng, +6 dB) in test",
        Q,
        _test(Q, 24, speech="espeak", speech_db=6.0),
    ),
    Condition("formant babble in test", P, _test(P, 25, speech="babble")),
    Condition("formant babble in training", variant(P, speech="babble"), _test(P, 26)),
    Condition("door slam in test", P, _test(P, 27, door_at=0.9)),
    Condition("door slam in test, joint Q", Q, _test(Q, 28, door_at=1.2)),
    Condition("door slam in training", variant(P, door_at=1.1), _test(P, 29)),
    # the instrument rings in the sub-bands where the stop's largest drop is: fitted as the stop can show there (session
    # 29, template.masked_signature), not as tuned (heard by the late path alone, 0.56 s after the stop, until then)
    Condition("second instrument from 0.8 s", P, _test(P, 30, second_rate=730.0, second_from=0.8)),
    Condition("second instrument throughout", Q, _test(Q, 31, second_rate=1230.0)),
    Condition("second instrument in training", variant(P, second_rate=730.0, second_from=1.0), _test(P, 32)),
    Condition("fan", P, _test(P, 33, fan=True)),
    Condition("fan in training and test", variant(Q, fan=True), _test(Q, 34, fan=True)),
    Condition("mains hum", Q, _test(Q, 35, hum=True)),
    Condition("clipping at 3x RMS", P, _test(P, 36, clip_x_rms=3.0)),
    Condition("44.1 kHz", variant(P, sr=44_100), _test(P, 37, sr=44_100)),
    Condition("tuned at 48 kHz, test at 44.1 kHz", P, _test(P, 38, sr=44_100)),
    Condition("stereo test file", Q, _test(Q, 39, stereo=True)),
    Condition("stereo training and test", variant(P, stereo=True), _test(P, 40, stereo=True)),
    Condition("quieter stop", variant(P, stop_kind="quieter"), _test(P, 41, stop_kind="quieter")),
    Condition(
        "quieter stop, joint Q, knocks",
        variant(Q, stop_kind="quieter"),
        _test(Q, 42, stop_kind="quieter", knocks_every_s=0.3),
    ),
    Condition("duller stop", variant(P, stop_kind="duller"), _test(P, 43, stop_kind="duller")),
    Condition("duller stop, speech", variant(Q, stop_kind="duller"), _test(Q, 44, stop_kind="duller", speech="espeak")),
    Condition("spectral-only stop", variant(P, stop_kind="spectral"), _test(P, 45, stop_kind="spectral")),
    Condition(
        "spectral-only stop, gain -12 dB, rate 900 Hz",
        variant(Q, stop_kind="spectral"),
        _test(Q, 46, stop_kind="spectral", gain_db=-12.0, rate=900.0),
    ),
    Condition("label 0.1 s late", P, _test(P, 47), label_s=2.1, warn=True),
    Condition("label 0.1 s early", Q, _test(Q, 48), label_s=1.9, warn=True),
    Condition("label where nothing changes", variant(P, stop_at=None), _test(P, 49), label_s=1.5, expect="refused"),
    Condition("label 0.8 s off", P, _test(P, 50), label_s=1.2, expect="refused"),
    Condition("silent training file", variant(P, silence=True), _test(P, 51), expect="refused"),
    Condition("0.5 s of room sound before the stepping", P, _test(P, 54), lead_s=0.5),
    Condition("silence in test", P, variant(P, silence=True, seed=52), expect="silent"),
    Condition("constant in test", P, variant(P, constant=0.2, seed=53), expect="silent"),
    # both directions: the test's stop departs from stepping unlike the training's
    Condition("trained louder, test quieter", P, _test(P, 60, stop_kind="quieter"), group="cross"),
    Condition("trained louder, test quieter, joint Q", Q, _test(Q, 61, stop_kind="quieter"), group="cross"),
    Condition(
        "trained duller, test brighter",
        variant(Q, stop_kind="duller"),
        _test(Q, 62, stop_kind="brighter"),
        group="cross",
        known_failure="a rise in sub-bands the tuning saw fall: only drops are interference-proof; a rise the "
        "tuning never saw cannot be told from a new sound in the room without the steps' synchrony, which needs "
        "0.24 s of the stop (deviate 18.9), past the 50 ms latency budget; over the last 40 ms the synchronous level "
        "rises 26.1 dB, and a voice's harmonic on a step line gives up to 27 dB in 1 h of stepping (docs/audio-log.md, "
        "'a synchronous average over the last 30-50 ms'); the late path (round 12a) finds it 0.56 s after the stop, "
        "its onset 3 ms late: it fails the latency alone",
    ),
    Condition(
        "trained brighter, test duller",
        variant(P, stop_kind="brighter"),
        _test(P, 63, stop_kind="duller"),
        group="cross",
    ),
    Condition("trained louder, spectral-only stop in test", P, _test(P, 64, stop_kind="spectral"), group="cross"),
    Condition(
        "trained quieter, test louder",
        variant(Q, stop_kind="quieter"),
        _test(Q, 65, stop_kind="louder"),
        group="cross",
        known_failure="not heard: the louder stop lowers the stepping modes by 3 dB only, while the broad-drop "
        "threshold must stay above the stepping's own slow fluctuation (6 robust SDs: joint Q gets 1.0 spread); the "
        "step clock's lines see it in 0.24 s (deviate 19.2), past the 50 ms latency budget; over the last 40 ms its "
        "synchronous level rises 29.2 dB in one sub-band, adding -11 dB of the stepping's line power, and a voice's "
        "harmonic on a step line adds up to +1.2 dB in 1 h of stepping (docs/audio-log.md, 'a synchronous average over "
        "the last 30-50 ms'); the late path (round 12a) finds it 0.56 s after the stop, its onset 3 ms late: it "
        "fails the latency alone",
    ),
    Condition("brighter stop", variant(P, stop_kind="brighter"), _test(P, 66, stop_kind="brighter"), group="cross"),
    # hostile conditions nobody tuned for (written before the detector was changed for them)
    Condition("stop fades in over 150 ms", P, _test(P, 70, fade_s=0.15), late_s=0.15, group="hostile"),
    Condition("stop fades in over 150 ms, joint Q", Q, _test(Q, 71, fade_s=0.15), late_s=0.15, group="hostile"),
    Condition(
        "step rate drifts +-10 %",
        P,
        _test(P, 72, drift=0.1),
        group="hostile",
    ),
    Condition("step rate drifts +-10 %, joint Q", Q, _test(Q, 73, drift=0.1, stop_at=2.4), group="hostile"),
    Condition("8-bit audio", P, _test(P, 74, bits=8), group="hostile"),
    Condition("8-bit training and test", variant(Q, bits=8), _test(Q, 75, bits=8), group="hostile"),
    Condition("tuned at 48 kHz, test at 22.05 kHz", P, _test(P, 76, sr=22_050), group="hostile"),
    Condition("22.05 kHz training and test", variant(Q, sr=22_050), _test(Q, 77, sr=22_050), group="hostile"),
    # a recording that starts mid-traverse, already at the stop: the detector fires as soon as its
    # template is learned, with the start of listening as the onset (see docs/audio.md)
    Condition(
        "starts at the stop",
        P,
        _test(P, 78, stop_at=0.0),
        late_s=0.25,
        group="hostile",
    ),
    Condition("starts at the stop, joint Q", Q, _test(Q, 79, stop_at=0.0), late_s=0.25, group="hostile"),
    # round 2: interference added before the detector was changed against speech (never developed against)
    Condition("radio music in test", P, _test(P, 80, music=True), group="hostile"),
    Condition("radio music in test, joint Q", Q, _test(Q, 81, music=True), group="hostile"),
    Condition("second talker (espeak-ng, high voice) in test", P, _test(P, 82, speech="espeak2"), group="hostile"),
    Condition("second talker, joint Q, +3 dB", Q, _test(Q, 83, speech="espeak2", speech_db=3.0), group="hostile"),
]


@dataclass
class Outcome:
    refused: str | None = None
    warnings: tuple[str, ...] = ()
    events: tuple[float, ...] = ()  # detected_at_s
    onsets: tuple[float, ...] = ()
    late: tuple[bool, ...] = ()  # found late by the late path (round 12a), per event
    true_stop_s: float | None = None
    late_s: float = 0.0

    @property
    def hits(self) -> list[int]:
        if self.true_stop_s is None:
            return []
        lo, hi = self.true_stop_s - TOL_S, self.true_stop_s + TOL_S + self.late_s
        return [i for i, o in enumerate(self.onsets) if lo <= o <= hi]

    @property
    def false_alarms(self) -> int:
        return len(self.events) - min(1, len(self.hits))

    @property
    def latency_s(self) -> float | None:
        h = self.hits
        return None if not h or self.true_stop_s is None else self.events[h[0]] - self.true_stop_s

    @property
    def fast_latency_s(self) -> float | None:
        """The latency of a stop the fast path heard (None for one found late: the latency targets are the fast
        path's, and a late find fails its condition on latency)."""
        h = self.hits
        return None if h and self.late and self.late[h[0]] else self.latency_s

    @property
    def onset_error_s(self) -> float | None:
        h = self.hits
        return None if not h or self.true_stop_s is None else self.onsets[h[0]] - self.true_stop_s


def _needs_espeak(c: Condition) -> bool:
    return any((sp or "").startswith("espeak") for sp in (c.train.speech, c.test.speech))


def run(c: Condition) -> Outcome:
    x, sr = render(c.train)
    label = c.label_s if c.label_s is not None else (c.train.stop_at or 1.5)
    try:
        tu = tune(x, sr, label, seed=0)
    except TuningError as e:
        return Outcome(refused=str(e))
    y, sr_t = render(c.test)
    if y.ndim == 2:
        y = y.mean(axis=1)
    if c.lead_s:
        room = 10 ** (-65 / 20) * np.random.default_rng(c.test.seed).standard_normal(int(c.lead_s * sr_t))
        y = np.concatenate((room.astype(np.float32), y))
    try:
        tu_t = tu.for_sample_rate(sr_t)
    except ValueError as e:  # listen refuses this tuning at this sample rate
        return Outcome(refused=f"listen: {e}")
    events = detect(y, tu_t, block=1024, confirm_s=CONFIRM_S, late=True)  # as listen --late reports them
    return Outcome(
        warnings=tuple((tu.checks or {}).get("warnings", [])),
        events=tuple(e.detected_at_s for e in events),
        onsets=tuple(e.onset_s for e in events),
        late=tuple(e.found_late for e in events),
        true_stop_s=(c.test.stop_at or 0.0) + c.lead_s if not (c.test.silence or c.test.constant is not None) else None,
        late_s=c.late_s,
    )


def found_late(c: Condition, o: Outcome) -> bool:
    """The stop found once, by the late path alone, with its onset right and no false alarm (the latency fails)."""
    return c.expect == "found" and len(o.hits) == 1 and o.false_alarms == 0 and o.late[o.hits[0]]


def passed(c: Condition, o: Outcome) -> bool:
    if c.expect == "refused":
        return o.refused is not None
    if o.refused is not None:
        return False
    if c.expect == "silent":
        return not o.events
    label_warned = any("disagrees" in w for w in o.warnings)
    return (
        len(o.hits) == 1 and o.false_alarms == 0 and label_warned == c.warn and (o.latency_s or 1.0) <= 0.050 + c.late_s
    )


_CACHE: dict[str, Outcome] = {}


def outcome(c: Condition) -> Outcome:
    if c.name not in _CACHE:
        _CACHE[c.name] = run(c)
    return _CACHE[c.name]


@pytest.mark.parametrize("cond", CONDITIONS, ids=[c.name for c in CONDITIONS])
def test_condition(cond: Condition) -> None:
    if _needs_espeak(cond) and espeak_speech(48_000) is None:
        pytest.skip("espeak-ng is not installed (apt-get install espeak-ng); the formant-babble conditions stand in")
    o = outcome(cond)
    if cond.known_failure:
        assert not passed(cond, o), f"{cond.name} passes now: drop its known_failure"
        pytest.xfail(cond.known_failure)
    assert passed(cond, o), (o.refused, o.warnings, o.events, o.onsets, o.true_stop_s)


def test_latency_targets_over_the_battery() -> None:
    lat = [
        o.fast_latency_s
        for c in CONDITIONS
        if not (_needs_espeak(c) and espeak_speech(48_000) is None) and c.late_s == 0
        for o in [outcome(c)]
        if o.fast_latency_s is not None
    ]
    assert len(lat) >= 30
    assert np.median(lat) <= 0.030 and np.percentile(lat, 95) <= 0.050, lat


def table() -> str:
    rows = [f"{'condition':48s} {'result':8s} {'found':>5s} {'FA':>3s} {'latency ms':>10s} {'onset err ms':>12s}  note"]
    for c in CONDITIONS:
        o = outcome(c)
        lat = f"{1e3 * o.latency_s:.1f}" if o.latency_s is not None else "-"
        err = f"{1e3 * o.onset_error_s:+.1f}" if o.onset_error_s is not None else "-"
        note = ("refused: " + o.refused[:60]) if o.refused else "; ".join(w[:60] for w in o.warnings)
        ok = "pass" if passed(c, o) else ("xfail" if c.known_failure else "FAIL")
        if not passed(c, o) and found_late(c, o):
            ok = "late"  # found late, onset right: fails the 50 ms latency alone
            note = "found late (the late path), onset right; " + note
        found = str(len(o.hits)) if o.true_stop_s is not None else "-"
        rows.append(f"{c.name:48s} {ok:8s} {found:>5s} {o.false_alarms:>3d} {lat:>10s} {err:>12s}  {note}")
    lat_all = [o.fast_latency_s for o in _CACHE.values() if o.fast_latency_s is not None and o.late_s == 0]
    errs = [abs(o.onset_error_s) for o in _CACHE.values() if o.onset_error_s is not None and o.late_s == 0]
    rows.append(
        f"latency over {len(lat_all)} stops: median {1e3 * np.median(lat_all):.1f} ms, "
        f"p95 {1e3 * np.percentile(lat_all, 95):.1f} ms; worst onset error {1e3 * max(errs):.1f} ms"
    )
    for g in ("core", "cross", "hostile"):
        cs = [c for c in CONDITIONS if c.group == g]
        ok = sum(passed(c, outcome(c)) for c in cs)
        late = sum(not passed(c, outcome(c)) and found_late(c, outcome(c)) for c in cs)
        more = f"; {late} more found late, onset right (they fail the latency)" if late else ""
        rows.append(f"{g}: {ok}/{len(cs)} pass{more}")
    return "\n".join(rows)


if __name__ == "__main__":
    print(table())
