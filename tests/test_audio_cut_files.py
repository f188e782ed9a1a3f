"""Audio files a recorder left cut short: a WAV whose header claims more than it holds, a FLAC that stops mid-frame.

Both are made here from a second of noise (audit33): libsndfile reads a truncated WAV's
samples without a word, and raises mid-read on a cut FLAC.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from typer.testing import CliRunner

from stickslip.audio.sources import AudioSourceError, read_wav, shortfall, truncation, wav_blocks
from stickslip.cli import app

runner = CliRunner()
RATE = 8000


def _noise(seconds: float) -> np.ndarray:
    return (0.1 * np.random.default_rng(0).standard_normal(int(seconds * RATE))).astype(np.float32)


def _cut(path: Path, keep: int) -> None:
    path.write_bytes(path.read_bytes()[:keep])


def test_a_wav_cut_short_is_said_with_what_its_header_claims_and_what_it_holds(tmp_path):
    whole = tmp_path / "whole.wav"
    sf.write(whole, _noise(2.0), RATE, subtype="PCM_16")  # 44-byte header, 32000 bytes of sound
    assert truncation(whole) is None
    cut = tmp_path / "cut.wav"
    cut.write_bytes(whole.read_bytes()[: 44 + 16000])
    why = truncation(cut)
    assert why is not None and "the header says 2.000 s of sound but the file holds 1.000 s" in why
    x, rate = read_wav(cut)  # read as before: what it holds
    assert (x.size, rate) == (8000, RATE)
    # a streaming recorder's placeholder length (0xFFFFFFFF) claims nothing; neither does a file that is not a WAV
    raw = bytearray(whole.read_bytes())
    raw[40:44] = struct.pack("<I", 0xFFFFFFFF)
    (tmp_path / "stream.wav").write_bytes(bytes(raw))
    (tmp_path / "text.wav").write_text("not audio\n")
    assert truncation(tmp_path / "stream.wav") is None and truncation(tmp_path / "text.wav") is None
    # the commands say it before anything else (before this warning: only "lasts 1.000 s")
    r = runner.invoke(app, ["tune", str(cut), "--stop-at", "1.5", "-o", str(tmp_path / "t.json"), "--rate", "1000"])
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines[0].startswith("warning: ") and "holds 1.000 s: it was cut short" in lines[0], r.stderr
    assert lines[-1].startswith("error: --stop-at 1.5 s is not inside the recording, which lasts 1.000 s"), r.stderr


def test_a_flac_cut_mid_frame_is_one_line_not_a_traceback(tmp_path):
    f = tmp_path / "cut.flac"
    sf.write(f, _noise(3.0), RATE, subtype="PCM_16")
    _cut(f, f.stat().st_size // 2)
    with pytest.raises(AudioSourceError, match=r"cut\.flac: damaged or cut short: not readable past \d+\.\d+ s"):
        for _ in wav_blocks(f, block=1024):
            pass
    out = tmp_path / "t.json"
    r = runner.invoke(app, ["tune", str(f), "--stop-at", "0.5", "-o", str(out), "--rate", "1000"])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "damaged or cut short" in lines[0], r.stderr
    assert not out.exists()


@pytest.mark.skipif("MP3" not in sf.available_formats(), reason="this libsndfile writes no MP3")
def test_an_mp3_cut_after_its_header_is_read_as_far_as_it_goes_and_said(tmp_path):
    """An MP3's Xing header claims the whole length; cut in half, SoundFile.blocks counted to that length and filled
    the rest with its buffer unfilled: the last block again (block 1024) or uninitialised memory (up to 1.8e18 seen;
    block 65536). Read now until the decoder gives nothing: only what the file holds, said in one warning."""
    whole = tmp_path / "whole.mp3"
    sf.write(whole, _noise(4.0), RATE, format="MP3", subtype="MPEG_LAYER_III")
    cut = tmp_path / "cut.mp3"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    claimed = sf.info(cut).frames
    full, _ = read_wav(whole)
    for block in (1024, 1 << 16):
        x = np.concatenate([b for b, _ in wav_blocks(cut, block=block)])
        assert 0.3 * claimed < x.size < 0.7 * claimed, (x.size, claimed)
        # the same samples as the whole file's (to the decoder's rounding; its last frame aside), nothing after
        assert np.abs(x).max() < 1.0 and np.allclose(x[:-1152], full[: x.size - 1152], atol=1e-6), block
    short = shortfall(cut, x.size)
    assert short is not None and f"the header says {claimed / RATE:.3f} s of sound but only " in short
    assert shortfall(whole, full.size) is None
    r = runner.invoke(app, ["tune", str(cut), "--stop-at", "3.5", "-o", str(tmp_path / "t.json"), "--rate", "1000"])
    assert r.exit_code == 2 and "could be read: it was cut short" in r.stderr, r.stderr


@pytest.mark.parametrize("fmt", ["RF64", "AIFF"])
def test_an_rf64_or_aiff_cut_short_is_said_too(tmp_path, fmt):
    """RF64 (a WAV over 4 GB: its length in the ds64 chunk) and AIFF (big-endian, the sound in SSND): cut in half."""
    whole = tmp_path / f"whole.{fmt.lower()}"
    sf.write(whole, _noise(2.0), RATE, format=fmt, subtype="PCM_16")
    assert truncation(whole) is None
    cut = tmp_path / f"cut.{fmt.lower()}"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    why = truncation(cut)
    assert why is not None and "the header says 2.00" in why and "but the file holds 0.99" in why, why
