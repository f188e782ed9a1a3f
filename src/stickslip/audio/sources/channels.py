"""Which channel of a multi-channel file carries the stepping: when the mean of the channels loses it.

Judged on the first ``seconds`` of the file, two ways (:func:`channel_problem`):

* *cancellation*: the mean's RMS is ``cancel_db`` or more below the loudest channel's:
  the channels carry the same sound in opposite polarity (a balanced microphone wired to
  both inputs of a stereo card) and their mean is near silence - or, when the mean is not
  as far below what channels sharing nothing would give, the sound is on one channel of
  many (a 6-channel recorder with one microphone: -16 dB) and the mean dilutes it;
* *drowned*: in some channel the step-rate line of the envelope stands at least the
  no-signal guard's ``min_line_db`` clear, and ``drowned_db`` or more clearer than in the
  mean, whose line stands less than ``weak_line_db`` clear: another channel (an open input
  picking up hum or noise) drowns it, or the channels hear each click at times far enough
  apart that their mean's envelope no longer beats at the step rate (two microphones some
  15 cm apart: each click heard twice, 0.44 ms apart, the mean's line at 1000 Hz falls
  from 40 to 9-14 dB and its envelope reads 2000 Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..features.stepclock import step_rate_hz
from ..paramfield import param
from .files import load_soundfile, open_error, regular
from .guard import GUARD, step_line_db

__all__ = ["CHANNELS", "ChannelParams", "channel_problem"]


@dataclass(frozen=True)
class ChannelParams:
    """When the mean of a file's channels loses the stepping sound."""

    seconds: float = param(2.0, "s", "the file's first this long is judged")
    cancel_db: float = param(
        -12.0, "dB", "the channels' mean this far below the loudest channel: they cancel (opposite polarity)"
    )
    drowned_db: float = param(6.0, "dB", "a step-rate line this much clearer in one channel than in the mean ...")
    weak_line_db: float = param(
        15.0, "dB", "... where the mean's stands less than this clear: the mean blurs the steps (other delays: 11 dB)"
    )
    dither: float = param(
        1e-4, "of the channel's RMS", "noise added before the lines are read: a pure tone's envelope has no floor"
    )


CHANNELS = ChannelParams()


def channel_problem(path: str | Path, seconds: float | None = None, p: ChannelParams = CHANNELS) -> str | None:
    """Why the mean of a multi-channel file's channels would lose the stepping sound, or ``None`` (module docstring).

    The step-rate lines are :func:`~stickslip.audio.sources.guard.step_line_db` at the rate
    heard in each channel (:func:`~stickslip.audio.features.stepclock.step_rate_hz`). The
    message names the channel to read instead (1-based, as ``--channel`` takes it).
    ``None`` for a mono file, a file too short to judge, or a mean that keeps the stepping.
    """
    seconds = p.seconds if seconds is None else seconds
    sf = load_soundfile()
    path_ = regular(path)
    try:
        with sf.SoundFile(str(path_)) as f:
            rate, n = int(f.samplerate), int(f.channels)
            if n < 2:
                return None
            data = f.read(frames=int(seconds * rate), dtype="float64", always_2d=True)
    except Exception as e:
        raise open_error(path_, e) from None
    data = np.nan_to_num(data, nan=0.0, posinf=1.0, neginf=-1.0)
    if data.shape[0] == 0:
        return None
    mix = data.mean(axis=1)
    rms = np.sqrt(np.mean(data**2, axis=0))
    mix_rms = float(np.sqrt(np.mean(mix**2)))
    loud = int(np.argmax(rms))
    if rms[loud] <= 0.0:
        return None
    mix_db = 20.0 * np.log10(max(mix_rms, 1e-300) / float(rms[loud]))
    if mix_db <= p.cancel_db:
        # below what channels that share nothing would give (the RMS of their sum over n) by as much: they cancel;
        # else the sound is on few of them and the mean dilutes it (one loud channel of 6: -16 dB)
        apart = float(np.sqrt(np.sum(rms**2))) / n
        cancel = 20.0 * np.log10(max(mix_rms, 1e-300) / apart) <= p.cancel_db
        why = "they carry the sound in opposite polarity and cancel" if cancel else (
            "the other channels carry little of its sound, and the mean dilutes it")
        return (
            f"{path_}: the mean of its {n} channels is {max(mix_db, -200.0):.0f} dB below channel {loud + 1}: "
            f"{why}; read one channel with --channel {loud + 1}"
        )
    # a noise floor 80 dB under each channel: a synthetic pure tone's envelope has no noise between its lines, and
    # any bin there would stand "clear" of a median that is only rounding error
    dither = p.dither * np.random.default_rng(0).standard_normal(data.shape)
    data = data + dither * rms
    mix = mix + dither[:, 0] * mix_rms
    lines = []
    for c in range(n):
        r = step_rate_hz(data[:, c], rate)
        line = step_line_db(data[:, c], rate, r) if math.isfinite(r) else -math.inf
        lines.append((line if math.isfinite(line) else -math.inf, r))
    best = max(range(n), key=lambda c: lines[c][0])
    line, r = lines[best]
    if line < GUARD.min_line_db:  # no channel shows stepping as the guard asks for it
        return None
    in_mix = step_line_db(mix, rate, r)
    if math.isfinite(in_mix) and in_mix < p.weak_line_db and line - in_mix >= p.drowned_db:
        return (
            f"{path_}: the step rate's line ({r:.0f} Hz) stands {line:.0f} dB clear in channel {best + 1} but "
            f"{in_mix:.0f} dB in the mean of the {n} channels: the mean blurs the steps (noise on another channel, or "
            f"microphones that hear each step at other times); read "
            f"channel {best + 1} alone with --channel {best + 1}"
        )
    return None
