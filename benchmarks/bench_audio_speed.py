"""The detector's kernels before and after they were made faster, side by side in one run (ratios, not times).

Each kernel that was made faster without changing a decision (``benchmarks/golden_audio.py``
compares every event, bit for bit) is timed here beside the code it replaced, which this file
keeps as the comparator, on the same inputs, in turns (A B A B ...); the outputs are checked
equal first:

* the float64 power spectra of ``frame_power_spectra`` (the guard's step-clock check and the
  tuning): ``numpy.fft.rfft`` before, ``scipy.fft.rfft`` after (bit-identical);
* the sub-band levels of live blocks of a few frames (``SubbandLevels``): the window, the bins'
  starts and the empty sub-bands made once per detector, not per block;
* the guard's dead-block test (``block_problem``) on float32 blocks: one pass over the block
  in its own precision, not a float64 copy and three passes;
* the guard's stepping check (``SignalGuard`` with a step rate) on live blocks of 1024: windows
  of whatever the blocks add up to (12 288 samples, an envelope FFT of 12 287 = 11 x 1117)
  before, windows of a length whose FFT is fast (12 001) after, the rest carried. The windows
  differ, so the check here is the verdict (stepping heard in every window), not bit-equality;
* the tuner's running template (``running_template``): a 2-D percentile filter with a
  (W, 1) footprint before, a 1-D one per sub-band after (the same element selected);
* the self-check's noise shaped like the stop's rise (``shaped_noise``) at the near-prime
  lengths a recording's stepping part has: ``numpy.fft`` before, ``scipy.fft`` after;
* a whole tuning (``tune``, three resolutions and their self-checks) with what its candidates
  share made once (``verification.Shared``: the frames' spectra of the recording, of its
  parts and of the sounds injected, kept by ``FramePowers``; the injected sounds themselves)
  against the same code with nothing kept (every detector computes its spectra, every
  self-check makes its sounds). The tunings are checked equal first. The continuum and fine
  spectra made for the chosen resolution only (not for every one tried) are in both.

Times are CPU times of this process (``time.process_time``): the machine may be shared.

The whole detector's speed is in ``bench_audio.py`` (its real-time table). On a shared,
loaded machine the ratios swing by factors: run it on a quiet one.

Run: ``.venv/bin/python benchmarks/bench_audio_speed.py`` (seconds).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from scipy.ndimage import percentile_filter

from stickslip.audio.change.template import TEMPLATE
from stickslip.audio.features.spectra import FramePowers, SubbandLevels, frame_power_spectra, window
from stickslip.audio.sources.guard import GUARD, SignalGuard, block_problem, step_line_db
from stickslip.audio.tuning import tune
from stickslip.audio.tuning.candidates import running_template
from stickslip.audio.tuning.inject import shaped_noise
from stickslip.audio.tuning.verification import Shared
from stickslip.sim.sound import render_traverse_recording


def _old_power_spectra(samples: np.ndarray, frame: int, hop: int) -> np.ndarray:
    x = np.asarray(samples, dtype=np.float64)
    frames = np.lib.stride_tricks.sliding_window_view(x, frame)[::hop]
    w, scale = window(frame)
    spec = np.fft.rfft(frames * w, axis=1)
    p = (spec.real**2 + spec.imag**2) * scale
    p[:, 0] *= 0.5
    if frame % 2 == 0:
        p[:, -1] *= 0.5
    return np.asarray(p)


def _old_levels(frames: np.ndarray, w: np.ndarray, scale: float, idx: np.ndarray) -> np.ndarray:
    from scipy import fft as sfft

    n, nb = frames.shape[0], idx.size - 1
    out = np.empty((n, nb))
    w32 = w.astype(np.float32)
    lo, hi = int(idx[0]), int(idx[-1])
    starts = (idx[:-1] - lo).astype(np.intp)
    for f0 in range(0, n, 1024):
        seg = np.asarray(frames[f0 : f0 + 1024], dtype=np.float32) * w32
        spec = sfft.rfft(seg, axis=1)[:, lo:hi]
        power = spec.real**2 + spec.imag**2
        band = np.add.reduceat(power, starts, axis=1, dtype=np.float64) * scale
        empty = idx[1:] <= idx[:-1]
        if empty.any():
            band[:, empty] = 0.0
        out[f0 : f0 + 1024] = 10 * np.log10(band + 1e-20)
    return out


def _old_block_problem(block: Any, floor: float = GUARD.floor) -> str | None:
    x = np.asarray(block, dtype=np.float64).ravel()
    if x.size == 0:
        return None
    if not np.all(np.isfinite(x)):
        return "non-finite samples"
    peak = float(np.max(np.abs(x)))
    if peak < floor:
        return "silence"
    if float(np.ptp(x)) < floor:
        return "a constant"
    if float(np.mean(np.abs(x) >= GUARD.clip_level * peak)) > GUARD.clip_share:
        return "clipping"
    return None


class _OldWindowGuard(SignalGuard):
    """The stepping check as it was: a window of whatever the blocks added up to, nothing carried."""

    def __post_init__(self) -> None:
        super().__post_init__()
        self.lines: list[float] = []

    def _check_stepping(self, x: np.ndarray) -> None:
        assert self.step_hz is not None
        self._window.append(np.asarray(x, dtype=np.float64))
        self._window_n += x.shape[0]
        if self._window_n < int(self.window_s * self.sample_rate):
            return
        w = np.concatenate(self._window)
        self._window, self._window_n = [], 0
        self.lines.append(step_line_db(w, self.sample_rate, self.step_hz))


def _guard_lines(guard: SignalGuard, blocks: list[np.ndarray]) -> list[float]:
    """The step-rate line of every window ``guard`` judged over ``blocks``, dB."""
    seen: list[float] = []
    if isinstance(guard, _OldWindowGuard):
        guard.lines = seen
    else:
        judge = guard._judge

        def spy(w: np.ndarray) -> None:
            seen.append(step_line_db(w, guard.sample_rate, float(guard.step_hz or 0.0)))
            judge(w)

        guard._judge = spy  # type: ignore[method-assign]
    for b in blocks:
        guard.check(b)
    return seen


def _old_running_template(V: np.ndarray, stepping: np.ndarray, hop_s: float, tau_s: float = 0.5) -> np.ndarray:
    q = 100 * TEMPLATE.quantile
    last = int(np.flatnonzero(stepping)[-1]) + 1
    W = max(TEMPLATE.chunk, int(round(tau_s / hop_s)))
    head = V[:last]
    pad = np.concatenate((np.repeat(np.percentile(head[:W], q, axis=0)[None, :], W, axis=0), head))
    run = percentile_filter(pad, q, size=(W, 1), origin=((W - 1) // 2, 0))[W:]
    out = np.empty_like(V)
    out[:last] = run
    out[last:] = run[-1]
    return np.asarray(out, dtype=np.float64)


def _old_shaped_noise(n: int, sample_rate: int, edges_hz: list[float], mean_square: np.ndarray, rng: Any) -> np.ndarray:
    w = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1 / sample_rate)
    idx = np.searchsorted(f, np.asarray(edges_hz, dtype=np.float64), side="left")
    gain = np.zeros(f.size)
    for b, ms in enumerate(np.asarray(mean_square, dtype=np.float64).tolist()):
        i0, i1 = int(idx[b]), int(idx[b + 1])
        if i1 <= i0 or not ms > 0.0:
            continue
        have = 2.0 * float(np.sum(np.abs(w[i0:i1]) ** 2)) / n**2
        gain[i0:i1] = np.sqrt(ms / max(have, 1e-300))
    return np.asarray(np.fft.irfft(w * gain, n), dtype=np.float64)


@contextmanager
def _nothing_shared() -> Iterator[None]:
    """Within: a tuning's candidates share nothing (no spectra kept, the self-check's sounds made per candidate)."""
    init, variants = Shared.__init__, Shared.variants

    def init_kept_none(self: Shared) -> None:
        init(self)
        self.powers = FramePowers(max_bytes=0)

    def variants_anew(self: Shared, *args: Any) -> dict[str, np.ndarray]:
        self._x = None
        return variants(self, *args)

    Shared.__init__, Shared.variants = init_kept_none, variants_anew  # type: ignore[method-assign]
    try:
        yield
    finally:
        Shared.__init__, Shared.variants = init, variants  # type: ignore[method-assign]


def _tune_unshared(x: np.ndarray, sr: int, stop_s: float) -> Any:
    with _nothing_shared():
        return tune(x, sr, stop_s, seed=0)


def side_by_side(name: str, a: Callable[[], Any], b: Callable[[], Any], turns: int = 15) -> float:
    """Median time of ``a`` (before) over ``b`` (after), run in turns; prints and returns the ratio."""
    ta, tb = [], []
    for _ in range(turns):
        for f, t in ((a, ta), (b, tb)):
            t0 = time.process_time()
            f()
            t.append(time.process_time() - t0)
    r = float(np.median(ta) / np.median(tb))
    print(f"  {name:58s} before / after = {r:5.2f}")
    return r


def main() -> None:
    rng = np.random.default_rng(1)
    print("kernels, before / after (1 = no faster); outputs checked equal first")
    x = (0.03 * rng.standard_normal(48_000)).astype(np.float32)
    for frame in (4096, 4410, 12_000):  # a power of two; 0.1 s at 44.1 kHz; the guard's 0.25 s window at 48 kHz
        old, new = _old_power_spectra(x, frame, frame // 2), frame_power_spectra(x, frame, frame // 2)
        assert np.array_equal(old, new), "the spectra differ"
        side_by_side(
            f"power spectra (float64), {frame}-sample frames, 1 s",
            lambda frame=frame: _old_power_spectra(x, frame, frame // 2),
            lambda frame=frame: frame_power_spectra(x, frame, frame // 2),
        )
    frame, hop = 512, 128
    w, scale = window(frame)
    idx = np.unique(np.linspace(10, 200, 25).astype(np.intp))
    view = np.lib.stride_tricks.sliding_window_view
    blocks = [view(x[i : i + 1024 + frame], frame)[::hop] for i in range(0, 40_000, 1024)]
    levels = SubbandLevels(w, scale, idx)
    assert all(np.allclose(_old_levels(f, w, scale, idx), levels(f), rtol=0, atol=1e-9) for f in blocks[:5])
    side_by_side(
        "sub-band levels, 39 live blocks of 8 frames",
        lambda: [_old_levels(f, w, scale, idx) for f in blocks],
        lambda: [levels(f) for f in blocks],
    )
    many = [(0.1 * rng.standard_normal(4096)).astype(np.float32) for _ in range(200)]
    assert [_old_block_problem(b) for b in many] == [block_problem(b) for b in many]
    side_by_side(
        "dead-block test, 200 float32 blocks of 4096",
        lambda: [_old_block_problem(b) for b in many],
        lambda: [block_problem(b) for b in many],
    )
    sr, n = 48_000, 10 * 48_000  # 10 s of clicks at 1 kHz over noise, as the guard hears a traverse
    clicks = 0.02 * rng.standard_normal(n)
    clicks[:: sr // 1000] += 0.5
    live = [clicks[i : i + 1024].astype(np.float32) for i in range(0, n - 1023, 1024)]
    old_lines = _guard_lines(_OldWindowGuard(sr, step_hz=1000.0), live)
    new_lines = _guard_lines(SignalGuard(sr, step_hz=1000.0), live)
    assert len(old_lines) == len(new_lines) == 39, (len(old_lines), len(new_lines))
    assert min(old_lines) > GUARD.min_line_db and min(new_lines) > GUARD.min_line_db, "stepping not heard"
    side_by_side(
        "guard's stepping check, 10 s in live blocks of 1024",
        lambda: [g.check(b) for g in [_OldWindowGuard(sr, step_hz=1000.0)] for b in live],
        lambda: [g.check(b) for g in [SignalGuard(sr, step_hz=1000.0)] for b in live],
    )
    x_tune, sr = render_traverse_recording(1, 1000.0, 2.0, 3.5, seed=11)
    V = 10.0 * np.log10(frame_power_spectra(x_tune, 512, 128)[:, 10:202].reshape(-1, 24, 8).sum(axis=2))
    stepping = np.arange(V.shape[0]) < V.shape[0] * 2 // 3
    hop_s = 128 / sr
    assert np.array_equal(_old_running_template(V, stepping, hop_s), running_template(V, stepping, hop_s))
    side_by_side(
        f"tuner's running template, {V.shape[0]} frames x {V.shape[1]} sub-bands",
        lambda: _old_running_template(V, stepping, hop_s),
        lambda: running_template(V, stepping, hop_s),
        turns=9,
    )
    edges = [300.0 * 2 ** (k / 3) for k in range(20)]
    ms = np.linspace(1e-6, 1e-4, 19)
    lengths = (94_445, 94_485, 94_488, 94_499, 94_500, 94_514)  # the stepping parts of four tuning recordings

    def noises(f: Callable[..., np.ndarray]) -> list[np.ndarray]:
        return [f(n, sr, edges, ms, np.random.default_rng([n, 7])) for n in lengths]

    assert all(np.array_equal(a, b) for a, b in zip(noises(_old_shaped_noise), noises(shaped_noise), strict=True))
    side_by_side(
        "self-check's shaped noise, 6 lengths near 94 500 samples",
        lambda: noises(_old_shaped_noise),
        lambda: noises(shaped_noise),
        turns=9,
    )
    talk, _ = render_traverse_recording(1, 1000.0, 2.0, 3.5, seed=11, babble=True, babble_db=-30.0)
    for what, y in (("clean, 1 resolution", x_tune), ("talk in the room, 3 resolutions", talk)):
        y = np.asarray(y, dtype=np.float64)
        assert _tune_unshared(y, sr, 2.0).to_dict() == tune(y, sr, 2.0, seed=0).to_dict(), "the tunings differ"
        side_by_side(
            f"tune, {what}: none shared",
            lambda y=y: _tune_unshared(y, sr, 2.0),
            lambda y=y: tune(y, sr, 2.0, seed=0),
            turns=5,
        )


if __name__ == "__main__":
    main()
