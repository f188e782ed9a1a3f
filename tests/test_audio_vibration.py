"""The limit switch on other sensors: an accelerometer's vibration stream and a position read-back.

The vibration is written here, by a generator of its own (not the sound synthesisers): an
accelerometer on the arm's base at 25 kHz, in vacuum (no room sound; a turbo pump's
lines and the sensor's noise instead). Each step is a half-sine force pulse of 40 us
driving three structural modes (decaying 2-5 ms); at the end stop the slider rests on
the stop, which stiffens the structure: the second mode moves up by 25 % and the pulse
transmits 4 dB more. Samples are in m/s^2 with a +-50 m/s^2 full scale.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from scipy.signal import lfilter
from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

from stickslip.audio.detector import detect, detector_for
from stickslip.audio.readback import ReadbackStopDetector
from stickslip.audio.sources import AudioSourceError, write_wav
from stickslip.audio.sources.vibration import SerialSamples, read_vibration

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

SR = 25_000


def accel(rate: float, stop_at: float, dur: float, seed: int, gain: float = 1.0) -> np.ndarray:
    """Acceleration, m/s^2, of the arm's base while stepping at ``rate`` Hz into the stop at ``stop_at`` s."""
    rng = np.random.default_rng(seed)
    n = int(dur * SR)
    t_steps = np.arange(0.0, dur, 1 / rate) + rng.normal(0, 10e-6, int(np.ceil(dur * rate)))
    t_steps = t_steps[(t_steps >= 0) & (t_steps < dur)]
    out = np.zeros(n)
    for at_stop in (False, True):
        sel = (t_steps >= stop_at) == at_stop
        x = np.zeros(n)
        x[(t_steps[sel] * SR).astype(int)] = rng.uniform(0.85, 1.15, int(sel.sum())) * (1.58 if at_stop else 1.0)
        x = np.convolve(x, np.sin(np.pi * np.arange(2) / 2) + 0.5)[:n]  # ~40 us half-sine pulse
        for k, (f, tau, g) in enumerate(((1300.0, 5e-3, 1.0), (3400.0, 3e-3, 0.8), (7100.0, 2e-3, 0.5))):
            if at_stop and k == 1:
                f *= 1.25
            r = np.exp(-1 / (tau * SR))
            out += g * lfilter([1.0], [1, -2 * r * np.cos(2 * np.pi * f / SR), r * r], x)
    t = np.arange(n) / SR
    out *= 2.0 / np.std(out[: int(stop_at * SR)])  # ~2 m/s^2 RMS while stepping
    out += sum(0.05 * np.sin(2 * np.pi * 833.3 * k * t + k) for k in (1, 2, 3))  # turbo pump lines
    out += 0.02 * rng.standard_normal(n)  # sensor noise
    return gain * out


def _csv(path, x: np.ndarray, with_time: bool) -> None:
    with open(path, "w", encoding="utf-8") as f:
        f.write(f"# accelerometer, m/s^2\n# sample_rate_hz={SR}\n")
        f.write("time_s,accel\n" if with_time else "accel\n")
        for i, v in enumerate(x):
            f.write(f"{i / SR:.7f},{v:.5f}\n" if with_time else f"{v:.5f}\n")


def test_the_same_detector_on_a_vibration_stream_from_csv_and_wav(tmp_path):
    _csv(tmp_path / "train.csv", accel(1000.0, 2.0, 3.0, seed=1), with_time=False)
    x, rate = read_vibration(tmp_path / "train.csv", full_scale=50.0)
    assert rate == SR and np.max(np.abs(x)) < 1.0
    tu = tune(x, rate, 2.0)
    assert tu.edges_hz[-1] <= 0.42 * SR
    lat = []
    for k, (r, stop_at, gain, with_time) in enumerate(((900.0, 1.4, 0.5, True), (1150.0, 1.1, 2.0, False))):
        _csv(tmp_path / f"test{k}.csv", accel(r, stop_at, stop_at + 0.5, seed=10 + k, gain=gain), with_time)
        y, _ = read_vibration(tmp_path / f"test{k}.csv", full_scale=50.0)
        (ev,) = detect(y, tu)
        assert abs(ev.onset_s - stop_at) <= 0.025
        lat.append(ev.detected_at_s - stop_at)
    write_wav(tmp_path / "test.wav", accel(1000.0, 1.3, 1.8, seed=20) / 50.0, SR)
    y, _ = read_vibration(tmp_path / "test.wav")
    (ev,) = detect(y, tu)
    assert abs(ev.onset_s - 1.3) <= 0.025
    assert max(lat) <= 0.050


def test_read_vibration_refuses_what_it_cannot_use(tmp_path):
    (tmp_path / "norate.csv").write_text("1\n2\n3\n")
    with pytest.raises(AudioSourceError, match="no sample rate"):
        read_vibration(tmp_path / "norate.csv")
    (tmp_path / "jitter.csv").write_text("0,1\n0.001,2\n0.0015,3\n")
    with pytest.raises(AudioSourceError, match="not uniformly spaced"):
        read_vibration(tmp_path / "jitter.csv")
    (tmp_path / "bad.csv").write_text("# sample_rate_hz=10000\n1\nx\n")
    with pytest.raises(AudioSourceError, match="bad.csv:3: not a number"):
        read_vibration(tmp_path / "bad.csv")
    with pytest.raises(AudioSourceError, match="no such file"):
        read_vibration(tmp_path / "missing.csv")


def test_read_vibration_checks_the_time_column(tmp_path):
    """audit25: a header 'time_ms,value' over times in seconds was read (its name skipped), 'volts,time_s' said the
    times were not uniformly spaced, and a --sample-rate other than the times' was taken over them, silently."""
    body = "".join(f"{k / 10000:.4f},{(-1) ** k * 0.1}\n" for k in range(50))
    p = tmp_path / "v.csv"
    p.write_text("time_s,value\n" + body)
    assert read_vibration(p)[1] == 10000 and read_vibration(p, sample_rate=10000)[1] == 10000
    for name in ("time_ms", "t [us]", "Time(min)"):
        p.write_text(f"{name},accel\n" + body)
        with pytest.raises(AudioSourceError) as e:
            read_vibration(p)
        assert str(e.value) == (f"{p}: the time column is named {name!r}: times are read in seconds: convert them "
                                "and name the column time_s")
    p.write_text("volts,time_s\n" + body)
    with pytest.raises(AudioSourceError) as e:
        read_vibration(p)
    assert str(e.value) == f"{p}: the header names 'volts','time_s': the time column comes first (time_s,value)"
    p.write_text("time_s,value\n" + body)
    with pytest.raises(AudioSourceError) as e:
        read_vibration(p, sample_rate=25000)
    assert str(e.value) == (f"{p}: its times say 10000 Hz but 25000 Hz is given (--sample-rate or a sample_rate_hz "
                            "line): keep the one that is right")
    runner, app = _cli()
    r = runner.invoke(app, ["tune", str(p), "--stop-at", "0.002", "-o", str(tmp_path / "t.json"), "--sample-rate",
                            "25000"])
    assert r.exit_code == 2 and r.stderr.startswith("error: ") and "its times say 10000 Hz" in r.stderr, r.output
    assert not (tmp_path / "t.json").exists()


def test_read_vibration_odd_encodings_and_rate_lines(tmp_path):
    """Found by tests/test_fuzz_files.py: a traceback, Python's codec words, a BOM that hid the rate, a second rate."""
    body = "".join(f"{float(v)!r}\n" for v in np.random.default_rng(1).normal(0.0, 0.1, 50))
    p = tmp_path / "a.csv"
    p.write_bytes(b"\xef\xbb\xbf# sample_rate_hz=5000\r\n" + body.replace("\n", "\r\n").encode())  # Excel's UTF-8
    x, rate = read_vibration(p)
    assert rate == 5000 and x.size == 50
    p.write_text("# sample_rate_hz=5000\n" + body, encoding="utf-16")
    with pytest.raises(AudioSourceError, match=r"a.csv: not UTF-8 text \(byte 0xff at offset 0\)"):
        read_vibration(p)
    p.write_text("# sample_rate_hz=1.2.3\n" + body)
    with pytest.raises(AudioSourceError, match=r"a.csv:1: the sample rate '1.2.3' is not a number"):
        read_vibration(p)
    p.write_text("# sample_rate_hz=5000\n# sample_rate_hz=8000\n" + body)
    with pytest.raises(AudioSourceError, match=r"a.csv:2: a second sample rate, 8000 Hz after 5000 Hz"):
        read_vibration(p)
    p.write_text("# sample_rate_hz=5000\n# sample_rate_hz=5000\n" + body)
    assert read_vibration(p)[1] == 5000 and read_vibration(p, sample_rate=8000)[1] == 8000  # the given rate wins
    p.write_text("# sample_rate_hz=5000\n" + body + "1.5e308\n")  # full scale 1.25 x that is infinite: all zeros
    with pytest.raises(AudioSourceError, match="data row 51 holds 1.5e[+]308, too large for a sample"):
        read_vibration(p)


class _FakeSerial:
    def __init__(self, values: np.ndarray):
        self._f = io.BytesIO("".join(f"{v:.5f}\r\n" for v in values).encode())

    def readline(self) -> bytes:
        return self._f.readline()


def test_a_live_serial_stream_feeds_the_detector_in_blocks():
    x = accel(1000.0, 2.0, 3.0, seed=3)
    tu = tune(x / 50.0, SR, 2.0, self_check=False)
    y = accel(1000.0, 0.9, 1.4, seed=4)
    src = SerialSamples(sample_rate=SR, block=256, full_scale=50.0, serial=_FakeSerial(y))
    det = detector_for(tu)
    events = []
    with pytest.raises(AudioSourceError, match="no vibration samples"):
        for block in src:
            assert block.shape == (256,)
            events += det.feed(block)
    (ev,) = events
    assert abs(ev.onset_s - 0.9) <= 0.025


def test_position_readback_stops_when_the_position_stalls():
    """A capacitive sensor at 1 kHz: 50 nm steps at 500 Hz, the stop at 0.6 s, sensor noise 5 nm."""
    rng = np.random.default_rng(5)
    t = np.arange(0, 1.0, 1e-3)
    pos = 50e-9 * np.floor(np.minimum(t, 0.6) * 500) + 5e-9 * rng.standard_normal(t.size)
    det = ReadbackStopDetector(1000.0, min_motion=40e-9, window_s=0.02)
    events = [e for i in range(0, t.size, 64) for e in det.feed(pos[i : i + 64])]
    (ev,) = events
    assert abs(ev.onset_s - 0.6) <= 0.005 and 0.015 <= ev.detected_at_s - 0.6 <= 0.03
    assert ReadbackStopDetector.uses_audio is False


# ---------------------------------------------------------------- the command line: CSV files and a live serial sensor


def _cli():
    from typer.testing import CliRunner

    from stickslip.cli import app

    return CliRunner(), app


def test_tune_and_listen_take_a_csv_of_vibration_samples(tmp_path):
    runner, app = _cli()
    _csv(tmp_path / "train.csv", accel(1000.0, 2.0, 3.0, seed=5), with_time=False)
    _csv(tmp_path / "test.csv", accel(1100.0, 1.2, 1.8, seed=6, gain=3.0), with_time=True)
    out = tmp_path / "acc.json"
    r = runner.invoke(app, ["tune", str(tmp_path / "train.csv"), "--stop-at", "2.0", "-o", str(out), "--json"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["listen", str(tmp_path / "test.csv"), "--tuning", str(out), "--json"])
    assert r.exit_code == 0, r.output
    import json

    (ev,) = json.loads(r.stdout)
    assert abs(ev["onset_s"] - 1.2) <= 0.025 and ev["detected_at_s"] - 1.2 <= 0.050
    # a CSV without a rate needs --sample-rate; a WAV refuses it; a sample that is not a number is named by its row
    y = accel(1000.0, 1.0, 1.5, seed=7)
    (tmp_path / "norate.csv").write_text("\n".join(f"{v:.5f}" for v in y))
    r = runner.invoke(app, ["listen", str(tmp_path / "norate.csv"), "--tuning", str(out)])
    assert r.exit_code == 2 and "--sample-rate" in r.output
    r = runner.invoke(app, ["listen", str(tmp_path / "norate.csv"), "--tuning", str(out), "--sample-rate", str(SR)])
    assert r.exit_code == 0 and r.output.count("stop: detected") == 1, r.output
    write_wav(tmp_path / "t.wav", y / 50.0, SR)
    r = runner.invoke(app, ["listen", str(tmp_path / "t.wav"), "--tuning", str(out), "--sample-rate", str(SR)])
    assert r.exit_code == 2 and "carries its own rate" in r.output
    (tmp_path / "nan.csv").write_text(f"# sample_rate_hz={SR}\n0.1\n0.2\nnan\n")
    r = runner.invoke(app, ["listen", str(tmp_path / "nan.csv"), "--tuning", str(out)])
    assert r.exit_code == 2 and "data row 3 holds nan" in r.output


@pytest.mark.skipif(not hasattr(__import__("os"), "openpty"), reason="a pseudo-terminal stands in for the serial port")
def test_listen_on_a_serial_vibration_sensor(tmp_path, monkeypatch):
    # an Arduino-like bridge sends one ASCII sample per line on a serial port; listen --serial hears the stop live,
    # and says so in one line when the sensor falls silent
    import os
    import threading
    import tty

    import serial

    runner, app = _cli()
    tu = tune(accel(1000.0, 2.0, 3.0, seed=8) / 50.0, SR, 2.0, self_check=False)
    out = tmp_path / "acc.json"
    tu.save(out)
    master, slave = os.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    y = accel(1000.0, 0.9, 1.5, seed=9)
    payload = "".join(f"{v:.4f}\r\n" for v in y).encode()

    # pyserial empties the input when it opens the port, as a sensor's samples before the opening are lost too:
    # the bridge starts sending once the port is open (stream time 0 is the first sample read)
    opened = threading.Event()
    real_open = serial.serial_for_url

    def open_then_signal(*args, **kwargs):
        port_ = real_open(*args, **kwargs)
        opened.set()
        return port_

    monkeypatch.setattr(serial, "serial_for_url", open_then_signal)

    def send() -> None:
        opened.wait(timeout=30)
        sent = 0
        while sent < len(payload):  # a pseudo-terminal takes what its buffer holds: the rest is written again
            sent += os.write(master, payload[sent : sent + 4096])

    writer = threading.Thread(target=send, daemon=True)
    writer.start()
    try:
        r = runner.invoke(app, ["listen", "--serial", port, "--tuning", str(out), "--json"])
    finally:
        writer.join(timeout=10)
        os.close(master)
        os.close(slave)
    assert r.exit_code == 2 and "no vibration samples for 2 s" in r.output  # the sensor fell silent: one line
    import json

    events = [json.loads(ln) for ln in r.stdout.splitlines() if ln.startswith("{")]
    assert len(events) == 1 and abs(events[0]["onset_s"] - 0.9) <= 0.025


def test_one_sample_rate_range_for_files_the_serial_listener_and_record(tmp_path):
    runner, app = _cli()
    tu = tmp_path / "t.json"
    tune(accel(1000.0, 2.0, 3.0, seed=8) / 50.0, SR, 2.0, self_check=False).save(tu)
    for rate in ("10", "nan", "2e6"):
        r = runner.invoke(app, ["listen", "--serial", "/dev/ttyACM0", "--sample-rate", rate, "--tuning", str(tu)])
        # nan: refused as not a finite number by every float option of the CLI (issue 34), before the range
        why = "not a finite number" if rate == "nan" else "--sample-rate must be 1000-1000000 Hz"
        assert r.exit_code == 2 and "--sample-rate" in r.output and why in r.output, r.output
    (tmp_path / "slow.csv").write_text("# sample_rate_hz=10\n" + "0.1\n" * 50)
    with pytest.raises(AudioSourceError, match="outside 1000-1000000 Hz"):
        read_vibration(tmp_path / "slow.csv")


@pytest.mark.parametrize("sep, header", [("\n", "# sample_rate_hz=25000\n"), (";", "time_s;value\n")])
def test_read_vibration_decimal_commas_are_named(tmp_path, sep, header):
    """audit41: samples a spreadsheet in a decimal-comma language wrote (0,0021; or 0,00004;0,0021 with ';').

    Before: one column of them read as two (0 and 21), refused as 'the times are not uniformly spaced'; with ';'
    as 'every row must hold ...'; neither said what was wrong."""
    x = np.random.default_rng(2).normal(0.0, 0.1, 40)
    if sep == "\n":
        body = "".join(f"{v:.5f}\n".replace(".", ",") for v in x)
    else:
        body = "".join(f"{k / 25000:.6f};{v:.5f}\n".replace(".", ",") for k, v in enumerate(x))
    p = tmp_path / "a.csv"
    p.write_text(header + body)
    with pytest.raises(AudioSourceError) as e:
        read_vibration(p)
    first = body.splitlines()[0]
    assert str(e.value) == (f"{p}:2: {first!r} is written with decimal commas: save the samples with decimal points "
                            "(0.0021, not 0,0021)")
