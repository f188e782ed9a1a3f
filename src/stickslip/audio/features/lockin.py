"""The step lines' power in phase with the steps' own clock, the clock followed from the sound.

A joint's step lines are in phase with its steps: demodulated at ``k`` times the step rate in
short frames, line ``k`` keeps one phase from frame to frame (as far as the step clock keeps
time). Music, a voice or a radio on or beside a line does not: a note off the line by ``df``
turns by ``df`` cycles a second against it. The power *in phase* over a stretch (the squared
magnitude of the frames' mean, ``|mean z|^2``) is the joint's line alone, less what the
added sound happens to leave in phase with it.

The clock a traverse commands is not quite the steps' clock: a controller whose step
intervals jitter wanders from it (0.4 % a step: 3.9 rad at 7 kHz over 500 steps), a
divided crystal runs tens of ppm off it, and each burst restarts its phase. So the clock is
followed from the sound: per frame, the lines 1 to ``harmonics`` demodulated at the rate,
the clock's offset (cycles of the step period) the one within ``slew`` of the last frame's
that best matches a running template of those lines, or anywhere in the cycle where that
matches ``reacquire`` times better (a burst began). Each line votes by its phase alone (its
match divided by its running power): a note louder than the joint on one line does not lead
the clock.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["demodulate", "follow_clock", "locked_powers"]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def demodulate(x: FloatArray, sample_rate: float, rate_hz: float, ks: Sequence[int], frame: int) -> ComplexArray:
    """``x`` demodulated at the lines ``k * rate_hz`` over whole frames of ``frame`` samples (frames x lines).

    The commanded clock's phase runs on from the first sample: ``z[f, j] = sum_n x[n] exp(-2 pi i k_j rate n / fs)``
    over frame ``f``'s samples ``n``.
    """
    n_frames = x.size // frame
    k = np.asarray(ks, dtype=np.float64)
    if n_frames == 0 or k.size == 0:
        return np.zeros((n_frames, k.size), dtype=np.complex128)
    j = np.arange(frame, dtype=np.float64)
    inside = -2 * np.pi * np.outer(j, k) * rate_hz / sample_rate  # the phase within a frame, rad
    start = np.exp(-2j * np.pi * np.outer(np.arange(n_frames) * frame, k) * rate_hz / sample_rate)
    frames = x[: n_frames * frame].reshape(n_frames, frame).astype(np.float64)
    z = frames @ np.cos(inside) + 1j * (frames @ np.sin(inside))  # two real products: a mixed one is far slower
    return np.asarray(z * start, dtype=np.complex128)


def follow_clock(
    z: ComplexArray, ks: Sequence[int], slew: float, reacquire: float, memory: float = 0.05, near_n: int = 41,
    whole_n: int = 100,
) -> FloatArray:
    """The steps' clock offset per frame (cycles of the step period) followed from the demodulated lines ``z``.

    Parameters
    ----------
    z : array (frames x lines)
        The lines ``ks`` demodulated at the commanded rate (:func:`demodulate`).
    ks : sequence of int
        Their harmonic numbers.
    slew : float
        The offset moves at most this from frame to frame (cycles)...
    reacquire : float
        ...unless the best offset anywhere in the cycle matches the template this many times better.
    memory : float
        The share by which the running template and each line's running power follow a frame (1).
    near_n, whole_n : int
        Offsets tried within the slew, and over the whole cycle (a grid of ``1 / whole_n`` cycles).

    Returns
    -------
    array
        The offset per frame, cycles (the first frame's is 0: the template is its lines).
    """
    k = np.asarray(ks, dtype=np.float64)
    near = np.linspace(-slew, slew, near_n)
    whole = np.arange(whole_n) / float(whole_n)
    turn_near, turn_whole = (np.exp(-2j * np.pi * np.outer(g, k)) for g in (near, whole))
    off = np.zeros(z.shape[0])
    if z.shape[0] == 0:
        return off
    tmpl, th = z[0].copy(), 0.0
    power = np.abs(z[0]) ** 2 + 1e-300
    for f in range(z.shape[0]):
        cross = z[f] * np.conj(tmpl) / power  # each line one vote: a loud note on one line does not lead the clock
        local = np.real(turn_near @ (cross * np.exp(-2j * np.pi * k * th)))  # offsets th + near
        best = int(np.argmax(local))
        anywhere = np.real(turn_whole @ cross)
        far = int(np.argmax(anywhere))
        if anywhere[far] > reacquire * max(local[best], 0.0):
            th = float(whole[far])
        else:
            th = float(th + near[best])
        off[f] = th
        tmpl = (1.0 - memory) * tmpl + memory * z[f] * np.exp(-2j * np.pi * k * th)
        power = (1.0 - memory) * power + memory * np.abs(z[f]) ** 2
    return off


def locked_powers(z: ComplexArray, ks: Sequence[int], off: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per line: the power in phase with the followed clock (``|mean z|^2``, the frames turned by their offset) and
    the power in all (``mean |z|^2``); their ratio is 1 for a line locked to the clock, about ``1 / frames`` for
    sound of random phase."""
    k = np.asarray(ks, dtype=np.float64)
    if z.shape[0] == 0:
        return np.zeros(k.size), np.zeros(k.size)
    turned = z * np.exp(-2j * np.pi * np.outer(off, k))
    locked = np.abs(turned.mean(axis=0)) ** 2
    whole = np.mean(np.abs(z) ** 2, axis=0)
    return np.asarray(locked, dtype=np.float64), np.asarray(whole, dtype=np.float64)
