"""The hour's generator (:mod:`hour_sound`) heard as a traverse hears it: a joint tuned on its own quiet 1000 Hz
recording (:mod:`fan_sound`'s tuning scene), the confirming detector told the commanded rate and fed block by block.

One place for the tests that run the product's detector over an hour's stream, whatever rule they switch."""

from __future__ import annotations

from functools import cache

from fan_sound import SR, Arm, render, tuning_scene
from hour_sound import Hour, stream
from tuned import tune

from stickslip.audio.confirm import ConfirmedStopDetector, ConfirmParams
from stickslip.audio.detector import detector_for
from stickslip.audio.events import StopEvent
from stickslip.audio.tuningfile import Tuning

__all__ = ["hear", "heard_by", "joint_tuning"]


@cache
def joint_tuning(arm: int) -> Tuning:
    """Joint ``arm`` tuned on its own quiet 1000 Hz recording (once per process)."""
    return tune(render(tuning_scene(Arm(arm))), SR, 2.0)


def heard_by(h: Hour, tu: Tuning, params: ConfirmParams | None = None) -> tuple[list[StopEvent], ConfirmedStopDetector]:
    """The confirmed events of ``h`` streamed block by block, the commanded rate told, and the detector (its log)."""
    det = ConfirmedStopDetector(detector_for(tu), params=params)
    det.reset(0.0, step_rate_hz=h.rate)
    return [e for block in stream(h) for e in det.feed(block)] + det.finish(), det


def hear(h: Hour, tu: Tuning, params: ConfirmParams | None = None) -> list[StopEvent]:
    """The confirmed events of ``h`` (:func:`heard_by`)."""
    return heard_by(h, tu, params)[0]
