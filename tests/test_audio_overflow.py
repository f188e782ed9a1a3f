"""Audio the sound card dropped never becomes a count.

A live stream's time is its samples counted. When PortAudio reports an input overflow,
samples were lost, nobody knows how many, and everything after is early by that much: a
stop heard then gives a step count that is short. A traverse on a sound card refuses the
measurement (one line, nothing recorded), ``record`` writes no labelled file, and
``listen --mic`` warns. The sound card is faked here (PortAudio is not needed): the
simulator's sound, delivered as a sound card would, with an overflow flagged in one block.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)
from typer.testing import CliRunner

import stickslip.audio.sources as sources
from stickslip.audio.sources import Microphone
from stickslip.procedures.session import traverse_on_device
from stickslip.procedures.traverse import TraverseError
from stickslip.sim.arm import SimulatedMM3A

DAY = "2026-11-22"


class _Status:
    input_overflow = True

    def __bool__(self) -> bool:
        return True


class _OverflowingStream:
    """PortAudio's stream, faked: two blocks, the second flagged as an input overflow."""

    def __init__(self, callback: Callable[..., None], channels: int, blocksize: int, **kw: Any) -> None:
        self.callback, self.channels, self.blocksize = callback, channels, blocksize

    def start(self) -> None:
        self.callback(np.zeros((self.blocksize, self.channels), np.float32), self.blocksize, None, None)
        self.callback(np.zeros((self.blocksize, self.channels), np.float32), self.blocksize, None, _Status())

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass


def test_the_microphone_counts_the_overflows_portaudio_reports(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "sounddevice", types.SimpleNamespace(InputStream=_OverflowingStream))
    with Microphone(block=128) as mic:
        it = mic.blocks(timeout_s=0.05)
        next(it), next(it)
        assert mic.overflows == 1


class _SoundCardArm:
    """The simulator heard through a sound card: its own microphone hidden, its clock kept."""

    def __init__(self, sim: SimulatedMM3A) -> None:
        self._sim = sim

    def __getattr__(self, name: str) -> Any:
        if name == "microphone":
            raise AttributeError(name)
        return getattr(self._sim, name)


def _card(sim: SimulatedMM3A, overflow_at_block: int | None) -> type:
    class _Card:
        """A sound card that hears ``sim`` from when it is started; PortAudio flags an overflow at one block."""

        def __init__(self, sample_rate: int = 48_000, block: int = 1024, device: Any = None, channels: int = 1):
            self.overflows = 0
            self._n = 0

        def start(self) -> _Card:
            self._mic = sim.microphone(block=1024)
            return self

        def stop(self) -> None:
            pass

        def blocks(self, timeout_s: float = 2.0) -> Any:
            card = self

            class _Heard:  # the simulator's microphone, as the traverse's listener reads it, counting blocks
                def __call__(self) -> list[np.ndarray]:
                    got = card._mic()
                    for _ in got:
                        card._n += 1
                        if card._n == overflow_at_block:
                            card.overflows += 1
                    return got

                def skip_to(self, t_s: float | None = None) -> None:
                    card._mic.skip_to(t_s)

                @property
                def t_s(self) -> float:
                    return float(card._mic.t_s)

            return _Heard()

    return _Card


@pytest.fixture(scope="module")
def tuning() -> Any:
    sim = SimulatedMM3A(seed=5, day=DAY)
    samples, rate, stop_at = sim.labelled_recording(3, "+", before_s=2.0, after_s=1.0)
    return tune(samples, rate, stop_at, joint=3)


@pytest.mark.slow
def test_a_traverse_through_a_sound_card_that_dropped_audio_records_nothing(
    tuning: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same traverse through a faked sound card: without an overflow it counts the simulator's 12338 steps
    (within 0.5 %); with one overflow flagged 3 s in, it refuses in one line."""
    sim = SimulatedMM3A(seed=5, day=DAY)
    monkeypatch.setattr(sources, "Microphone", _card(sim, None))
    ok = traverse_on_device(_SoundCardArm(sim), 3, "+", sim.pose, DAY, tuning, progress=False)  # type: ignore[arg-type]
    assert ok.steps == pytest.approx(12338, rel=0.005)

    sim = SimulatedMM3A(seed=5, day=DAY)
    monkeypatch.setattr(sources, "Microphone", _card(sim, 150))
    with pytest.raises(TraverseError, match="the sound card dropped audio 1 time during the traverse") as e:
        traverse_on_device(_SoundCardArm(sim), 3, "+", sim.pose, DAY, tuning, progress=False)  # type: ignore[arg-type]
    assert "nothing recorded" in str(e.value) and "\n" not in str(e.value)


def test_listen_live_warns_when_the_sound_card_drops_audio(monkeypatch: pytest.MonkeyPatch) -> None:
    from stickslip.cli.audio import _warn_overflows

    class _Mic:
        overflows = 0

        def blocks(self) -> Iterator[np.ndarray]:
            for k in range(5):
                if k == 2:
                    self.overflows += 1
                yield np.zeros(16, np.float32)

    runner_err: list[str] = []
    import stickslip.cli.audio as cli_audio

    monkeypatch.setattr(cli_audio.err_console, "print", lambda text, **kw: runner_err.append(str(text)))
    assert len(list(_warn_overflows(_Mic()))) == 5
    assert len(runner_err) == 1 and "dropped audio (input overflow, 1 so far)" in runner_err[0]


def test_record_writes_nothing_when_the_sound_card_dropped_audio(
    tmp_path: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    import queue

    import stickslip.devices as devices
    from stickslip.cli import app

    class _Ctrl:
        def frequency(self, joint: int) -> float:
            return 4000.0

        def step(self, joint: int, n: int) -> None:
            pass

        def stop(self, joint: int) -> None:
            pass

        def close(self) -> None:
            pass

    class _DroppingMic:
        def __init__(self, sample_rate: int = 48_000, block: int = 1024, device: Any = None) -> None:
            self._queue: queue.Queue[np.ndarray] = queue.Queue()
            for k in range(12):
                self._queue.put(np.full((block, 1), 0.01 * (k + 1), np.float32))
            self.overflows = 1

        def start(self) -> _DroppingMic:
            return self

        def stop(self) -> None:
            pass

    monkeypatch.setattr(devices, "open_device", lambda url: _Ctrl())
    monkeypatch.setattr(sources, "Microphone", _DroppingMic)
    wav = tmp_path / "real.wav"
    r = CliRunner().invoke(
        app, ["record", str(wav), "--joint", "2", "--device", "mm3a:///dev/fake", "--steps", "400", "--stop-at-step",
              "300"],
    )  # fmt: skip
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip().startswith("error:")]
    assert len(lines) == 1 and "dropped audio 1 time while recording" in lines[0], r.stderr
    assert not wav.exists()
    # only the database, where record journals the joint it stepped (it was driven: the steps were sent)
    assert not [p for p in tmp_path.iterdir() if not p.name.startswith("stickslip-test.db")]
