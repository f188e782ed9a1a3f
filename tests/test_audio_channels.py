"""Multi-channel recordings: when the mean of the channels loses the stepping sound, and ``--channel``.

A stereo sound card with the microphone on one input gives files whose channels need not
agree: a balanced microphone wired to both inputs carries the sound in opposite polarity
(the mean cancels to the converter's last bits), and an open second input can carry hum or
noise louder than the stepping (the mean drowns it). The recordings come from the
battery's independent generator (``tests/support/battery_sound.py``) and ``tests/support/modal_sound.py``,
not from the project's simulator; the other channels are built here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from battery_sound import Scene, render, variant  # noqa: E402
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from stickslip.audio.features.stepclock import step_rate_hz  # noqa: E402
from stickslip.audio.sources import AudioSourceError, channel_problem, read_wav, wav_blocks  # noqa: E402
from stickslip.audio.sources.guard import GUARD, block_problem, step_line_db  # noqa: E402
from stickslip.cli import app  # noqa: E402

runner = CliRunner()
P = Scene("P", 1000.0, 2.0, 3.0, seed=1)
STOP = 1.6


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("channels")
    x, sr = render(P)
    sf.write(d / "train.wav", x, sr, subtype="FLOAT")
    y, _ = render(variant(P, seed=77, stop_at=STOP, dur=STOP + 0.6, rate=1000.0))
    rng = np.random.default_rng(5)
    n = y.size
    sf.write(d / "anti.wav", np.stack([y, -y], 1), sr)  # 16-bit: the mean keeps only rounding
    sf.write(d / "anti_near.wav", np.stack([y, -0.9 * y], 1), sr, subtype="FLOAT")
    sf.write(d / "noise_other.wav", np.stack([y, 0.3 * rng.standard_normal(n)], 1), sr, subtype="FLOAT")
    sf.write(d / "hum_other.wav", np.stack([y, 0.5 * np.sin(2 * np.pi * 50.0 * np.arange(n) / sr)], 1), sr)
    sf.write(d / "dead_other.wav", np.stack([y, np.zeros(n)], 1), sr, subtype="FLOAT")
    sf.write(d / "same.wav", np.stack([y, y], 1), sr, subtype="FLOAT")
    sf.write(d / "mono.wav", y, sr, subtype="FLOAT")
    args = ["tune", str(d / "train.wav"), "--stop-at", "2.0", "-o", str(d / "t.json"), "--no-self-check"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    return d


def test_sixteen_bit_silence_toggling_its_last_bit_is_silence_not_clipping() -> None:
    lsb = 1.0 / 32768.0
    toggling = lsb * np.where(np.random.default_rng(1).random(4096) < 0.5, 1.0, -1.0)
    assert block_problem(toggling) == "silence: only the converter's last bits toggle"
    assert block_problem(np.clip(np.random.default_rng(2).standard_normal(4096), -0.05, 0.05)) == "clipping"
    # the boundary: rails just above GUARD.quiet_rails are a clipped sound, just below the converter's last bits
    assert block_problem(1.01 * GUARD.quiet_rails * np.sign(toggling)) == "clipping"
    quiet = block_problem(0.99 * GUARD.quiet_rails * np.sign(toggling))
    assert quiet == "silence: only the converter's last bits toggle"


def test_channels_in_opposite_polarity_are_named_with_the_channel_to_read(files: Path) -> None:
    why = channel_problem(files / "anti.wav")
    assert why is not None and "opposite polarity" in why and "--channel" in why
    near = channel_problem(files / "anti_near.wav")  # 0.9: the mean is 20 log10(0.05) = -26 dB under channel 1
    assert near is not None and "-26 dB below channel 1" in near and "--channel 1" in near


def test_a_noisy_other_channel_that_drowns_the_stepping_is_named(files: Path) -> None:
    why = channel_problem(files / "noise_other.wav")
    assert why is not None and "channel 1" in why and "--channel 1" in why and "blurs the steps" in why


@pytest.mark.parametrize("name", ["hum_other", "dead_other", "same", "mono"])
def test_a_mean_that_keeps_the_stepping_is_not_warned_about(files: Path, name: str) -> None:
    # a dead second input halves the level (-6 dB), a pure hum tone adds no envelope line: the mean is fine
    assert channel_problem(files / f"{name}.wav") is None


def test_one_channel_is_read_alone_and_a_channel_that_is_not_there_is_one_line(files: Path) -> None:
    y1, sr = read_wav(files / "noise_other.wav", channel=0)
    y, _ = read_wav(files / "mono.wav")
    assert sr == 48_000 and np.array_equal(y1, y)
    with pytest.raises(AudioSourceError, match="has 2 channels \\(1 to 2\\): there is no channel 3"):
        next(wav_blocks(files / "same.wav", channel=2))
    with pytest.raises(AudioSourceError, match="has 1 channel: there is no channel 2"):
        read_wav(files / "mono.wav", channel=1)


def test_listen_warns_about_cancelling_channels_and_hears_the_stop_in_one(files: Path) -> None:
    t = str(files / "t.json")
    r = runner.invoke(app, ["listen", str(files / "anti.wav"), "--tuning", t, "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout) == []
    assert "opposite polarity" in r.stderr and "--channel" in r.stderr
    assert "silence: only the converter's last bits toggle" in r.stderr
    assert "the joint steps at" not in r.stderr  # no step rate is read from silence
    for ch in ("1", "2"):
        r = runner.invoke(app, ["listen", str(files / "anti.wav"), "--tuning", t, "--json", "--channel", ch])
        assert r.exit_code == 0, r.output
        (ev,) = json.loads(r.stdout)
        assert abs(ev["onset_s"] - STOP) <= 0.025, ev
        assert "opposite polarity" not in r.stderr


def test_listen_on_a_drowned_mean_misses_the_stop_and_its_channel_hears_it(files: Path) -> None:
    t = str(files / "t.json")
    r = runner.invoke(app, ["listen", str(files / "noise_other.wav"), "--tuning", t, "--json"])
    assert r.exit_code == 0 and json.loads(r.stdout) == [] and "--channel 1" in r.stderr, r.output
    r = runner.invoke(app, ["listen", str(files / "noise_other.wav"), "--tuning", t, "--json", "--channel", "1"])
    (ev,) = json.loads(r.stdout)
    assert abs(ev["onset_s"] - STOP) <= 0.025, ev


def test_tune_reads_one_channel(files: Path) -> None:
    x, sr = render(P)
    rng = np.random.default_rng(9)
    sf.write(files / "train_noisy.wav", np.stack([0.3 * rng.standard_normal(x.size), x], 1), sr, subtype="FLOAT")
    out = files / "t2.json"
    args = ["tune", str(files / "train_noisy.wav"), "--stop-at", "2.0", "-o", str(out), "--channel", "2"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["listen", str(files / "noise_other.wav"), "--tuning", str(out), "--json", "--channel", "1"])
    (ev,) = json.loads(r.stdout)
    assert abs(ev["onset_s"] - STOP) <= 0.025, ev


@pytest.mark.parametrize(
    "args,words",
    [
        (["--channel", "3"], ["there is no channel 3"]),
        (["--channel", "0"], ["--channel counts from 1"]),
        (["--channel", "-2"], ["--channel counts from 1"]),
    ],
)
def test_bad_channels_are_one_line(files: Path, args: list[str], words: list[str]) -> None:
    r = runner.invoke(app, ["listen", str(files / "same.wav"), "--tuning", str(files / "t.json"), *args])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and all(w in lines[0] for w in words), r.stderr


def test_channel_is_refused_for_a_csv_and_for_live_input(files: Path) -> None:
    (files / "v.csv").write_text("\n".join(str(v) for v in np.zeros(100)))
    r = runner.invoke(app, ["listen", str(files / "v.csv"), "--tuning", str(files / "t.json"), "--channel", "1"])
    assert r.exit_code == 2 and "is a CSV of samples" in r.stderr, r.output
    r = runner.invoke(app, ["tune", str(files / "v.csv"), "--stop-at", "0.001", "-o", str(files / "x.json"),
                            "--sample-rate", "48000", "--channel", "1"])  # fmt: skip
    assert r.exit_code == 2 and "is a CSV of samples" in r.stderr, r.output
    r = runner.invoke(app, ["listen", "--mic", "--tuning", str(files / "t.json"), "--channel", "1"])
    assert r.exit_code == 2 and "a live input is read as one channel" in r.stderr, r.output


@pytest.mark.slow
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    g=st.floats(0.3, 1.0),
    noise_db=st.floats(-60.0, -30.0),
    delay=st.integers(0, 48),
    seed=st.integers(0, 10_000),
)
@example(g=0.8125, noise_db=-30.0, delay=21, seed=0)  # a fresh draw (session 27): warned, and rightly
def test_two_microphones_of_the_same_polarity_are_warned_about_only_where_the_mean_blurs_the_steps(
    tmp_path: Path, g: float, noise_db: float, delay: int, seed: int
) -> None:
    """Two inputs hearing the same stepping (another gain, a delay of up to 1 ms, their own noise).

    Never the cancellation warning. The other warning only where the mean really loses the step rate: a
    delay of near half a step period in the envelope (21 samples, 0.44 ms at 48 kHz: each step heard twice)
    leaves the mean's envelope line at 1000 Hz under 15 dB, and the mean then reads 2000 Hz; the channel it
    names reads the true 1000 Hz. (A delay of half a period of a mode cancels that mode in the mean; the
    mean's RMS and, at most delays, its step line stay.)
    """
    y, sr = render(variant(P, seed=seed, stop_at=None, dur=2.5, rate=1000.0))
    rng = np.random.default_rng(seed)
    rms = float(np.sqrt(np.mean(y**2)))
    other = g * np.roll(y, delay) + rms * 10 ** (noise_db / 20) * rng.standard_normal(y.size)
    path = tmp_path / f"two_{seed}.wav"
    sf.write(path, np.stack([y, other], 1), sr, subtype="FLOAT")
    why = channel_problem(path)
    if why is None:
        return
    assert "opposite polarity" not in why, why
    named = int(why.rsplit("--channel ", 1)[1])
    alone = (y, other)[named - 1]
    mean = (y + other)[: 2 * sr] / 2
    assert abs(step_rate_hz(alone[: 2 * sr], sr) - 1000.0) < 10.0, why
    assert step_line_db(mean, sr, 1000.0) < 15.0 and 0.3 <= (delay / sr * 1000.0) % 1.0 <= 0.7, why


def test_a_few_damaged_samples_in_a_wide_file_are_damage_not_a_dead_input(files: Path) -> None:
    """Eight channels of noise with 100 NaNs in one: the damage is reported, the input is not called dead."""
    x = 0.01 * np.random.default_rng(0).standard_normal((48_000, 8))
    x[100:200, 3] = np.nan
    sf.write(files / "eight.wav", x, 48_000, subtype="FLOAT")
    r = runner.invoke(app, ["listen", str(files / "eight.wav"), "--tuning", str(files / "t.json"), "--json"])
    assert r.exit_code == 0 and json.loads(r.stdout) == [], r.output
    assert "100 samples are not numbers" in r.stderr and "carries no signal" not in r.stderr, r.stderr
    r = runner.invoke(app, ["listen", str(files / "eight.wav"), "--tuning", str(files / "t.json"), "--channel", "9"])
    assert r.exit_code == 2 and "has 8 channels (1 to 8): there is no channel 9" in r.stderr, r.output


def test_one_loud_channel_of_six_is_said_to_be_diluted_not_cancelled(tmp_path: Path) -> None:
    """A 6-channel recorder with the microphone on channel 4 and quiet noise on the others (audit33): the mean is
    -16 dB under channel 4 and was said to "carry the sound in opposite polarity and cancel"."""
    y, sr = render(variant(P, seed=3, stop_at=None, dur=2.5, rate=1000.0))
    rms = float(np.sqrt(np.mean(y**2)))
    six = 0.03 * rms * np.random.default_rng(3).standard_normal((y.size, 6))
    six[:, 3] = y
    sf.write(tmp_path / "six.wav", six, sr, subtype="FLOAT")
    why = channel_problem(tmp_path / "six.wav")
    assert why is not None and "-16 dB below channel 4" in why and "--channel 4" in why, why
    assert "dilutes" in why and "opposite polarity" not in why, why
    # the same recorder with channel 5 wired in opposite polarity to channel 4: that one cancels
    six[:, 4] = -y
    sf.write(tmp_path / "anti6.wav", six, sr, subtype="FLOAT")
    anti = channel_problem(tmp_path / "anti6.wav")
    assert anti is not None and "opposite polarity" in anti, anti
