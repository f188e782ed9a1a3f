"""Audio limit switch commands: ``record`` (a labelled recording), ``tune`` (from it) and ``listen``."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import typer

from . import app
from ._common import (
    console,
    db_option,
    device_url,
    err_console,
    fail,
    open_store,
    print_json,
    say,
    user_errors,
    warn,
    write_failure,
)
from ._output import CARRIAGE_RETURN, data_stream, styled

#: file suffixes read as a CSV of vibration samples (stickslip.audio.sources.vibration); anything else is audio
_CSV_SUFFIXES = (".csv", ".txt")

_SAMPLE_RATE_HELP = (
    "Samples per second, 1000-1000000 Hz, of a CSV of vibration samples that does not say it (a "
    "'# sample_rate_hz=...' line or a time_s column), or of a --serial sensor (default: the tuning's). WAV files "
    "carry their own."
)
_TUNE_SAMPLE_RATE_HELP = (  # tune has no --serial, and no tuning yet to take a rate from
    "Samples per second, 1000-1000000 Hz, of a CSV of vibration samples that does not say it (a "
    "'# sample_rate_hz=...' line or a time_s column): needed for such a CSV. WAV files carry their own."
)


def _check_sample_rate(sample_rate: float | None) -> None:
    """``fail`` unless ``--sample-rate`` is absent or one a vibration stream may have."""
    from ..audio.sources.vibration import VIBRATION, sample_rate_ok

    if sample_rate is not None and not sample_rate_ok(sample_rate):
        lo, hi = VIBRATION.sample_rate_range
        fail(f"--sample-rate must be {lo:.0f}-{hi:.0f} Hz, got {sample_rate:g}")


def _check_step_rate(step_rate: float | None) -> None:
    """``--rate`` (the step rate commanded, Hz), where given, is a step rate: one line and exit 2 otherwise."""
    if step_rate is not None and not (math.isfinite(step_rate) and 1.0 <= step_rate <= 1e5):
        fail(f"--rate must be a step rate of 1-100000 Hz, got {step_rate:g}")


def _is_csv(path: Path) -> bool:
    return path.suffix.lower() in _CSV_SUFFIXES


_CHANNEL_HELP = (
    "Read this channel of a multi-channel audio file alone (1: the first, left). Default: the mean of the "
    "channels, with a warning when that mean cancels (opposite polarity) or drowns the stepping sound."
)


def _channels(path: Path, channel: int | None) -> int | None:
    """The 0-based channel to read from ``path`` (None: the mean); warns when the mean loses the stepping, and when
    the file holds less than its header says (:func:`~stickslip.audio.sources.files.truncation`)."""
    from ..audio.sources import AudioSourceError, channel_problem, truncation

    if not _is_csv(path) and (cut := truncation(path)) is not None:
        warn(cut)

    if channel is not None:
        if _is_csv(path):
            fail(f"--channel is for a multi-channel audio file; {path} is a CSV of samples")
        if channel < 1:
            fail(f"--channel counts from 1 (the first channel), got {channel}")
        return channel - 1
    if _is_csv(path):
        return None
    try:
        why = channel_problem(path)
    except AudioSourceError as e:
        fail(str(e))
    if why is not None:
        warn(why)
    return None


def _load_recording(path: Path, sample_rate: float | None, channel: int | None = None) -> tuple[Any, int]:
    """Samples and rate of a WAV (any audio file soundfile reads) or of a CSV of vibration samples."""
    from ..audio.sources import AudioSourceError, read_wav
    from ..audio.sources.vibration import read_vibration

    if sample_rate is not None and not _is_csv(path):
        fail(f"--sample-rate is for a CSV of samples; {path} carries its own rate")
    ch = _channels(path, channel)  # refuses --channel for a CSV
    try:
        if _is_csv(path):
            return read_vibration(path, sample_rate)
        samples, rate = read_wav(path, ch)
    except AudioSourceError as e:
        fail(str(e))
    _warn_shortfall(path, samples.size)
    return samples, rate


def _warn_shortfall(path: Path, frames_read: int) -> None:
    """One warning line when ``path`` gave fewer frames than its header claims (not a CSV)."""
    from ..audio.sources import shortfall

    if not _is_csv(path) and (short := shortfall(path, frames_read)) is not None:
        warn(short)


@app.command()
def tune(
    recording: Path = typer.Argument(
        ...,
        help="WAV recording (or a CSV of vibration samples, one per row: value or time_s,value): stepping, then "
        "stepping against the end stop.",
        metavar="REC.wav",
    ),
    stop_at: float = typer.Option(..., "--stop-at", help="When the joint reached its stop, seconds from the start."),
    out: Path = typer.Option(
        ..., "--output", "-o", "--out",
        help="Where to write the tuning (JSON: sub-band edges in Hz, the stop's signature in dB).",
    ),
    joint: int = typer.Option(None, "--joint", "-j", help="Joint 1, 2 or 3 the recording belongs to."),
    min_band: float | None = typer.Option(
        None,
        "--min-band",
        help="--method band only: narrowest band considered, Hz (default 1400); keep it above your highest step "
        "rate.",
        show_default=False,
    ),
    method: str = typer.Option(
        "template",
        "--method",
        help="'template' (the spectral-template change detector) or 'band' (the version-1 band-power detector).",
    ),
    self_check: bool = typer.Option(
        True,
        "--self-check/--no-self-check",
        help="Check the tuning on the recording with knocks, babble, +-20 dB gain and a second click train added.",
    ),
    sample_rate: float = typer.Option(None, "--sample-rate", help=_TUNE_SAMPLE_RATE_HELP, show_default=False),
    channel: int = typer.Option(None, "--channel", help=_CHANNEL_HELP, show_default=False),
    json_out: bool = typer.Option(False, "--json", help="Print the tuning as JSON."),
    step_rate: float | None = typer.Option(
        None,
        "--rate",
        help=(
            "The step rate the controller commanded while recording, 1-100000 Hz ('stickslip record' writes it in the "
            "label): "
            "where another instrument steps in bursts at another rate, its pieces are left out (without it, refused)."
        ),
        show_default=False,
    ),
) -> None:
    """Tune the audio limit switch of one joint from a labelled recording.

    Learns the stepping sound's spectral template (sub-bands over the band where stepping
    is heard, never above 0.42 of the sample rate) and the end stop's signature: how
    much each sub-band changes at the stop, in dB (louder, quieter, duller or brighter).
    Candidates are scored on their worst stepping frames and verified best first on the
    recording; a label that disagrees with where the sound changes is a warning, one
    where nothing changes is refused. The self-check reports the expected false alarms
    per hour with interference added, and the latency. A CSV of accelerometer samples
    (a vacuum chamber, where no air carries the sound) is tuned the same way.

    Examples: stickslip tune joint2.wav --stop-at 4.2 --joint 2 -o joint2-tuning.json
              stickslip tune accel.csv --sample-rate 25000 --stop-at 4.2 -o accel-tuning.json
    """
    from ..audio.tuning import TuningError, tune_band
    from ..audio.tuning import tune as tune_

    if joint is not None and joint not in (1, 2, 3):
        fail(f"--joint must be 1, 2 or 3, got {joint}")
    if method not in ("template", "band"):
        fail(f"--method must be 'template' or 'band', got {method!r}")
    if min_band is not None and min_band < 0:
        fail(f"--min-band is a band's width, 0 Hz or more, got {min_band:g} Hz")
    if method == "template" and min_band is not None:
        warn(f"--min-band {min_band:g} Hz is for --method band; the template detector chooses its sub-bands itself")
    _check_step_rate(step_rate)
    _writable(out, "tuning")
    samples, rate = _load_recording(recording, sample_rate, channel)
    duration = samples.size / rate
    if samples.size == 0:
        fail(f"{recording} holds no samples (an empty or truncated recording): nothing to tune on")
    if not 0 < stop_at < duration:
        fail(
            f"--stop-at {stop_at:g} s is not inside the recording, which lasts {duration:.3f} s: the stop comes "
            "after some stepping and before the end, with the stop's sound after it"
        )
    try:
        if method == "band":
            if min_band is None:
                tuning = tune_band(samples, rate, stop_at, joint=joint)
            else:
                tuning = tune_band(samples, rate, stop_at, joint=joint, min_band_hz=min_band)
        else:
            tuning = tune_(samples, rate, stop_at, joint=joint, self_check=self_check, step_rate_hz=step_rate)
    except TuningError as e:
        fail(f"{recording}: {e}")
    try:
        tuning.save(out)
    except OSError as e:
        fail(write_failure(out, e))
    for w in (tuning.checks or {}).get("warnings", []):
        warn(w)
    if json_out:
        print_json(tuning.to_dict())
        return
    console.print(styled(f"tuning for {recording}", "bold"), f"(joint {joint if joint else '?'})")
    console.print(tuning.report(), highlight=False, soft_wrap=True)
    console.print(f"saved to {out}", soft_wrap=True)


@app.command()
def listen(
    recording: Path = typer.Argument(
        None, help="WAV file (or CSV of vibration samples) to listen to; or use --mic or --serial.", metavar="[REC.wav]"
    ),
    tuning_path: Path = typer.Option(..., "--tuning", help="Tuning JSON written by 'stickslip tune'."),
    mic: bool = typer.Option(False, "--mic", help="Listen live to the microphone until Ctrl-C."),
    audio_input: str = typer.Option(
        None,
        "--input",
        help="Audio input device (index or name) for --mic; `python -m sounddevice` lists them.",
    ),
    serial_port: str = typer.Option(
        None,
        "--serial",
        help="Listen live to a vibration sensor that sends one ASCII sample per line on this serial port "
        "(/dev/ttyACM0, COM3; an Arduino or DAQ bridge reading an accelerometer) until Ctrl-C.",
    ),
    sample_rate: float = typer.Option(None, "--sample-rate", help=_SAMPLE_RATE_HELP, show_default=False),
    channel: int = typer.Option(None, "--channel", help=_CHANNEL_HELP, show_default=False),
    confirm_s: float | None = typer.Option(
        None,
        "--confirm-s",
        help=(
            "Report a stop only once it persisted this long after the detector fired, 0-5 s (default 0.5: a real stop "
            "lasts, interference does not); events then appear this much later. 0: every fire, at once."
        ),
        show_default=False,
    ),
    step_clock: bool = typer.Option(
        False,
        "--step-clock/--no-step-clock",
        help=(
            "Also ask the step clock before reporting a stop: a real stop's clicks keep the steps' rhythm, talk, a "
            "radio or another instrument do not (fewer false alarms). Off by default: check first that your arm's "
            "stop is on the clock (docs/audio.md, 'The step clock and the late path'); where it is not, no stop is "
            "ever reported."
        ),
    ),
    late: bool = typer.Option(
        False,
        "--late/--no-late",
        help=(
            "Also report stops the detector never heard, found late on the step clock's lines (0.5-0.75 s after the "
            "stop, the onset estimated back; found_late in --json): a stop whose sound the tuning never saw (trained "
            "on a quieter stop, this one louder). Off by default (docs/audio.md, 'The step clock and the late path')."
        ),
    ),
    step_rate: float | None = typer.Option(
        None,
        "--rate",
        help=(
            "The step rate the controller commanded, 1-100000 Hz (a traverse tells the detector the same): the step "
            "clock is "
            "heard near it, and a stop is known at rates up to 25 % from the tuning's (without it, 12 %)."
        ),
        show_default=False,
    ),
    json_out: bool = typer.Option(
        False,
        "--json",
        help=(
            "Print a JSON list of events: detected_at_s, onset_s (s), level_db (dB, as the tuning's threshold), "
            "confirmed_at_s and confirmed_s (s; null with --confirm-s 0), onset_uncertain, found_late; with --mic "
            "one JSON object per line as they are confirmed."
        ),
    ),
) -> None:
    """Listen for end stops in a recording (or live) with a tuned detector.

    Prints each event: when it was detected, the estimated onset of the stop (s from
    the start) and the band level (dB, in the tuning's unit). A fire is reported once
    the stop persisted for --confirm-s (default 0.5 s); a recording that ends sooner
    after a fire reports it if it persisted so far, and says how long it was heard.

    Examples: stickslip listen joint2.wav --tuning joint2-tuning.json --json
              stickslip listen --mic --tuning joint2-tuning.json
              stickslip listen --serial /dev/ttyACM0 --sample-rate 25000 --tuning accel-tuning.json
    """
    from ..audio.confirm import CONFIRM_S, check_confirm_s
    from ..audio.detector import Tuning, TuningFileError

    if (recording is not None) + mic + (serial_port is not None) != 1:
        fail("give one of: a recording REC.wav, --mic, or --serial PORT")
    if audio_input is not None and not mic:
        fail("--input picks the sound card --mic listens to; a recording or --serial sensor has none")
    _check_sample_rate(sample_rate)
    _check_step_rate(step_rate)
    try:
        confirm_s = check_confirm_s(CONFIRM_S if confirm_s is None else confirm_s)
    except ValueError as e:
        fail(f"--confirm-s: {e}")
    if step_clock and confirm_s == 0:
        fail("--step-clock judges a stop while it is confirmed: give --confirm-s > 0")
    if late and confirm_s == 0:
        fail("--late runs beside the confirmed detector: give --confirm-s > 0")
    try:
        tuning = Tuning.load(tuning_path)
    except TuningFileError as e:
        fail(str(e))
    except OSError as e:
        fail(f"cannot read tuning {tuning_path}: {e.strerror or e}")
    if channel is not None and recording is None:
        fail("--channel reads one channel of a recording (a live input is read as one channel)")
    if mic:
        _listen_live(tuning, audio_input, json_out, confirm_s, step_clock, late, step_rate)
        return
    if serial_port is not None:
        _listen_serial(tuning, serial_port, sample_rate, json_out, confirm_s, step_clock, late, step_rate)
        return
    _listen_file(recording, tuning, tuning_path, sample_rate, channel, json_out, confirm_s, step_clock, late, step_rate)


def _listen_file(
    recording: Path,
    tuning: Any,
    tuning_path: Path,
    sample_rate: float | None,
    channel: int | None,
    json_out: bool,
    confirm_s: float,
    step_clock: bool,
    late: bool,
    step_rate: float | None = None,
) -> None:
    """``listen`` on a recording: read it in blocks through the procedure, print the notes, warnings and stops."""
    from ..audio.sources import AudioSourceError, wav_blocks
    from ..procedures.listen import ListenSettings, TuningMismatch, listen_blocks

    if tuning.method == "band":
        err_console.print(
            f"note: {tuning_path} is a version-1 band-power tuning; re-tune with 'stickslip tune' for the "
            "spectral-template detector (it rejects knocks and hears quieter or duller stops)",
            highlight=False,
        )
    blocks: Iterable[tuple[Any, float]]
    if _is_csv(recording):
        samples, csv_rate = _load_recording(recording, sample_rate, channel)
        blocks = ((samples[i : i + (1 << 16)], csv_rate) for i in range(0, samples.size, 1 << 16))
    else:
        if sample_rate is not None:
            fail(f"--sample-rate is for a CSV of samples or --serial; {recording} carries its own rate")
        blocks = wav_blocks(recording, block=1 << 16, channel=_channels(recording, channel))
    try:
        report = listen_blocks(blocks, tuning, ListenSettings(confirm_s, step_clock, late, step_rate))
    except TuningMismatch as e:
        fail(f"tuning {tuning_path} does not fit {recording} at {e.rate} Hz: {e}")
    except AudioSourceError as err:
        fail(str(err))
    if report.samples == 0:  # an empty or truncated file
        fail(f"{recording} holds no samples (an empty or truncated recording): nothing to listen to")
    _warn_shortfall(recording, report.samples)
    for t_s, why in report.stopped:
        _note_stopped(t_s, why)
    for line in report.warnings(str(recording), tuning):
        warn(line)
    if json_out:
        print_json([e.to_dict() for e in report.events])
        return
    if not report.events:
        console.print("no end stop heard")
    for ev in report.events:
        say(_event_line(ev, tuning.level_unit, confirm_s, 4))


def _event_line(ev: Any, unit: str, confirm_s: float, digits: int) -> str:
    """One event for a person: detection, onset, level, and how it was confirmed."""
    line = (
        f"stop: detected at {ev.detected_at_s:.{digits}f} s, onset {ev.onset_s:.{digits}f} s, "
        f"level {ev.level_db:.2f} {unit}"
    )
    if ev.onset_uncertain:
        line += "; onset uncertain (when the stop began is not known: a traverse refuses it; measure again)"
    if getattr(ev, "found_late", False):
        line += "; found late on the step clock (the detector did not hear it; its onset estimated back)"
    elif ev.confirmed_s is not None:
        if ev.confirmed_s < confirm_s - 1e-9:
            line += f"; the recording ended {ev.confirmed_s:.3f} s after it fired (it persisted so far)"
        else:
            line += f"; persisted {ev.confirmed_s:.3f} s"
    return line


def _print_live(ev: Any, tuning: Any, json_out: bool, confirm_s: float) -> None:
    if json_out:
        out = data_stream()  # one JSON object per line, as it is confirmed: written and flushed now
        out.write(json.dumps(ev.to_dict()) + "\n")
        out.flush()
    else:
        say(_event_line(ev, tuning.level_unit, confirm_s, 3))


def _listen_serial(
    tuning: Any,
    port: str,
    sample_rate: float | None,
    json_out: bool,
    confirm_s: float,
    step_clock: bool,
    late: bool = False,
    step_rate: float | None = None,
) -> None:
    """Live vibration samples from a serial port through the same detector as sound."""
    from ..audio.sources import AudioSourceError
    from ..audio.sources.vibration import SerialSamples
    from ..procedures.listen import ListenSettings, TuningMismatch, detector_for

    rate = int(round(sample_rate)) if sample_rate is not None else int(tuning.sample_rate)
    try:
        det = detector_for(tuning, rate, ListenSettings(confirm_s, step_clock, late, step_rate))
    except TuningMismatch as e:
        fail(f"the tuning does not fit {rate} Hz samples: {e}")
    try:
        src = SerialSamples(port, sample_rate=rate)
    except AudioSourceError as err:
        fail(str(err))
    if not json_out:
        err_console.print(f"listening to {port} at {rate} Hz; Ctrl-C to stop", highlight=False)
    _report_live(det, src.blocks(), src.close, tuning, json_out, confirm_s, f"{port}: ")


def _listen_live(
    tuning: Any,
    device: str | None,
    json_out: bool,
    confirm_s: float,
    step_clock: bool,
    late: bool = False,
    step_rate: float | None = None,
) -> None:
    from ..audio.confirm import confirming
    from ..audio.detector import detector_for
    from ..audio.sources import AudioSourceError, Microphone

    dev: int | str | None = int(device) if device is not None and device.isdigit() else device
    mic = Microphone(sample_rate=tuning.sample_rate, block=1024, device=dev)
    det = confirming(detector_for(tuning), confirm_s, step_clock=step_clock, late=late)
    det.reset(0.0, step_rate)
    try:
        mic.start()
    except AudioSourceError as err:
        fail(str(err))
    if not json_out:
        err_console.print(f"listening at {tuning.sample_rate} Hz; Ctrl-C to stop")
    _report_live(det, _warn_overflows(mic), mic.stop, tuning, json_out, confirm_s, "")


def _warn_overflows(mic: Any) -> Iterator[Any]:
    """The microphone's blocks, with a warning on stderr each time the sound card drops audio."""
    seen = 0
    for block in mic.blocks():
        if mic.overflows > seen:
            seen = mic.overflows
            err_console.print(
                f"warning: the sound card dropped audio (input overflow, {seen} so far): the times of what follows "
                "are early by what was lost; close other programs that use the sound card",
                highlight=False,
                soft_wrap=True,
            )
        yield block


def _note_stopped(t_s: float, why: Any) -> None:
    """One line on stderr: the stepping stopped at ``t_s`` (s), which is not an end stop (audio.confirm.pause)."""
    err_console.print(
        f"note: the stepping stopped at {t_s:.2f} s (the sound fell {-why.drop_db:.0f} dB, to the room's, and no "
        "stepping was heard in it): a pause, not an end stop, so no stop is reported there",
        highlight=False,
        soft_wrap=True,
    )


def _report_live(
    det: Any, blocks: Iterator[Any], close: Any, tuning: Any, json_out: bool, confirm_s: float, where: str
) -> None:
    """Feed a live source's blocks to ``det`` and print each event as it comes, until Ctrl-C; then ``close()``."""
    from ..audio.sources import AudioSourceError
    from ..procedures.listen import listen_live

    try:
        listen_live(det, blocks, lambda ev: _print_live(ev, tuning, json_out, confirm_s), _note_stopped)
    except AudioSourceError as err:
        fail(f"{where}{err}")
    finally:
        close()


@app.command()
def record(
    out: Path = typer.Argument(
        ..., help="WAV file to write (a JSON label file is written beside it).", metavar="OUT.wav"
    ),
    joint: int = typer.Option(..., "--joint", "-j", help="Joint 1, 2 or 3 to drive into its end stop."),
    direction: str = typer.Option(
        "+", "--direction", metavar="<+|->", help="'+' (towards the upper stop) or '-'. (-d is the device.)"
    ),
    device: str | None = typer.Option(
        None,
        "--device",
        "-d",
        help="Controller URL: sim://, mm3a:///dev/ttyUSB0, anc300://host (default: device in the config file, "
        "else sim://).",
    ),
    audio_input: str = typer.Option(None, "--input", help="Audio input device for a real controller (index or name)."),
    serial_port: str = typer.Option(
        None,
        "--serial",
        help="Real controller: record a vibration sensor on this serial port instead of a sound card (one ASCII "
        "sample per line; give its --sample-rate).",
    ),
    sample_rate: float = typer.Option(
        None, "--sample-rate", help="With --serial: the sensor's samples per second, Hz.", show_default=False
    ),
    steps: int = typer.Option(None, "--steps", help="Real controller: steps to issue in all (past the stop)."),
    stop_at_step: int = typer.Option(
        None, "--stop-at-step", help="Real controller: the step count at which the joint reaches its stop (the label)."
    ),
    key: bool = typer.Option(
        False, "--key", help="Real controller: label the stop by pressing Enter when you hear it."
    ),
    before: float | None = typer.Option(
        None, "--before", help="Simulator: seconds of stepping before the stop, 0.3-60 (default 2).",
        show_default=False,
    ),
    after: float | None = typer.Option(
        None, "--after", help="Simulator: seconds against the stop, 0.3-60 (default 1).", show_default=False
    ),
    tune_out: Path = typer.Option(None, "--tune", help="Also tune from the recording and write the tuning here."),
    json_out: bool = typer.Option(False, "--json", help="Print the label (and tuning) as JSON."),
    db: str | None = db_option(
        " A real controller's joint is kept there as uncertain (between where it was and its stop) until referenced."
    ),
) -> None:
    """Record a joint stepping into its end stop, labelled, for 'stickslip tune'.

    On the simulator (sim://) the joint is placed --before seconds from its stop and the
    label is the simulator's own stop time. On a real controller the joint steps --steps
    steps at its set frequency while the sound card records; the label is the time of
    step --stop-at-step (you know the joint's travel in steps), or the moment you press
    Enter (--key; your reaction time, ~0.2 s, makes it late: tune corrects a label that
    disagrees with the sound and says so). A live meter shows the level of the stepping
    band (dBFS, with the band in Hz; learned from the first 0.5 s while the joint steps),
    the band the tuning will listen to.

    Example: stickslip record j2.wav --joint 2 --device sim://?seed=3 --tune j2-tuning.json
    """
    from ..audio.sources import AudioSourceError
    from ..devices import DeviceError, open_device
    from ..models import direction_label

    if joint not in (1, 2, 3):
        fail(f"--joint must be 1, 2 or 3, got {joint}")
    try:
        sign_label = direction_label(direction)
    except ValueError as e:
        fail(str(e))
    if out.suffix.lower() != ".wav":
        fail(f"{out}: record writes a WAV file: name it .wav (its label is written beside it, as .json)")
    _writable(out, "recording")
    _writable(out.with_suffix(".json"), "label")
    if tune_out is not None:
        _writable(tune_out, "tuning")
    with user_errors(DeviceError, AudioSourceError):
        ctrl = open_device(device_url(device))
        try:
            from ..sim.arm import SimulatedMM3A

            if isinstance(ctrl, SimulatedMM3A):  # the simulator labels its own stop
                if serial_port is not None:
                    fail("--serial records a sensor beside a real controller; the simulator renders its own sound")
                _not_on_simulator(steps=steps, stop_at_step=stop_at_step, key=key or None, input=audio_input,
                                  sample_rate=sample_rate)
                before, after = 2.0 if before is None else before, 1.0 if after is None else after
                if not (0.3 <= before <= 60 and 0.3 <= after <= 60):
                    fail("--before and --after must be 0.3-60 s")
                samples, rate, stop_at = ctrl.labelled_recording(joint, sign_label, before_s=before, after_s=after)
                how = "the simulator's stop time"
            else:
                if before is not None or after is not None:
                    fail("--before and --after place the simulator's joint; a real controller steps --steps steps, "
                         "labelled by --stop-at-step or --key")
                if serial_port is not None and audio_input is not None:
                    fail("give --input (a sound card) or --serial (a vibration sensor), not both")
                if (serial_port is None) != (sample_rate is None):
                    fail("--serial and --sample-rate go together (the sensor's samples carry no clock)")
                _check_sample_rate(sample_rate)
                with _driving(db, device_url(device), joint, sign_label):
                    samples, rate, stop_at, how = _record_real(
                        ctrl,
                        joint,
                        sign_label,
                        steps,
                        stop_at_step,
                        key,
                        audio_input,
                        serial_port,
                        int(round(sample_rate)) if sample_rate is not None else None,
                    )
            hz = float(ctrl.frequency(joint))  # the rate commanded while recording
        finally:
            ctrl.close()
    _finish_recording(out, samples, rate, float(stop_at), how, joint, sign_label, tune_out, json_out, hz)


def _not_on_simulator(**given: object) -> None:
    """Refuse (one line, exit 2) a real controller's option given for the simulator, where it would do nothing."""
    names = [f"--{k.replace('_', '-')}" for k, v in given.items() if v is not None]
    if names:
        fail(
            f"{', '.join(names)}: {'a real controller option' if len(names) == 1 else 'real controller options'}; "
            "the simulator places the joint --before seconds from its stop and labels the stop itself"
        )


@contextmanager
def _driving(db: str | None, device: str, joint: int, sign_label: str) -> Iterator[None]:
    """Under ``device``'s lock, with ``joint`` kept uncertain towards the stop ``record`` drives it into.

    ``record`` stepped a real controller's joint into its stop with no lock (beside a
    ``move`` in another terminal, or under ``stickslip serve``) and left the kept position
    where it was before: the next ``move`` planned from a place the joint had left.
    """
    from ..procedures.move import DeviceBusy, driven_towards_stop

    stop = "upper" if sign_label == "+" else "lower"
    why = f"'stickslip record' drove it towards its {stop} stop"
    with open_store(db) as store, user_errors(DeviceBusy):
        with driven_towards_stop(store, device, joint, 1 if sign_label == "+" else -1, why):
            yield


def _writable(path: Path, what: str) -> None:
    """Refuse (one line, exit 2) an output path where a folder, FIFO or device stands, before anything is done."""
    from ..records import writable_target

    with user_errors():
        writable_target(path, what)


def _finish_recording(
    out: Path, samples: Any, rate: int, stop_at: float, how: str, joint: int, sign_label: str,
    tune_out: Path | None, json_out: bool, step_rate_hz: float | None = None,
) -> None:
    """Write the recording and its label (and the tuning, with --tune), then say what was written; ``step_rate_hz``:
    the rate commanded while recording, Hz, in the label and told to the tuning."""
    from ..audio.sources import write_wav
    from ..records import atomic_write_text

    try:
        write_wav(out, samples, rate)
    except OSError as e:
        fail(write_failure(out, e))
    try:
        label = {
            "recording": str(out),
            "stop_at_s": round(float(stop_at), 6),
            "sample_rate_hz": int(rate),
            "joint": joint,
            "direction": sign_label,
            "label_from": how,
            "step_rate_hz": step_rate_hz,
        }
        atomic_write_text(out.with_suffix(".json"), json.dumps(label, indent=2) + "\n")
    except OSError as e:  # the recording is new: its label (an older one, if kept) must not be taken for its own
        fail(f"{write_failure(out.with_suffix('.json'), e)}; the recording {out} was written (its stop is at "
             f"{float(stop_at):.6g} s)")
    result: dict[str, object] = {"label": label}
    if tune_out is not None:
        from ..audio.tuning import TuningError
        from ..audio.tuning import tune as tune_

        try:
            tuning = tune_(samples, rate, float(stop_at), joint=joint, step_rate_hz=step_rate_hz)
            tuning.save(tune_out)
        except TuningError as e:
            fail(f"{out}: {e}")
        except OSError as e:
            fail(write_failure(tune_out, e))
        result["tuning"] = tuning.to_dict()
        for w in (tuning.checks or {}).get("warnings", []):
            warn(w)
    if json_out:
        print_json(result)
        return
    console.print(
        f"recorded {samples.size / rate:.2f} s at {rate} Hz to {out}; stop at {stop_at:.3f} s ({how})",
        highlight=False,
        soft_wrap=True,
    )
    if tune_out is None:
        console.print(
            f"next: stickslip tune {out} --stop-at {stop_at:.3f} --joint {joint} -o tuning-joint{joint}.json",
            highlight=False,
            soft_wrap=True,
        )
    else:
        console.print(f"tuned and saved to {tune_out}", soft_wrap=True)


def _record_real(
    ctrl: Any,
    joint: int,
    direction: str,
    steps: int | None,
    stop_at_step: int | None,
    key: bool,
    audio_input: str | None,
    serial_port: str | None = None,
    serial_rate: int | None = None,
) -> tuple[Any, int, float, str]:
    """Step a real controller into its stop while the sound card (or a serial sensor) records; a meter on stderr."""
    import threading
    import time

    import numpy as np

    from ..audio.meter import BandMeter
    from ..audio.sources import Microphone

    if steps is None or steps < 1:
        fail("a real controller needs --steps (how many to issue, past the stop)")
    if (stop_at_step is None) == (not key):
        fail("give --stop-at-step N or --key to label the stop")
    if stop_at_step is not None and not 1 <= stop_at_step < steps:
        fail(f"--stop-at-step must be 1..{steps - 1}")
    hz = float(ctrl.frequency(joint))
    dev: int | str | None = int(audio_input) if audio_input is not None and audio_input.isdigit() else audio_input
    rate = serial_rate or 48_000
    mic: Any = _SerialRecorder(serial_port, rate).start() if serial_port else None
    if mic is None:
        mic = Microphone(sample_rate=rate, block=1024, device=dev).start()
    meter = BandMeter(rate)
    pressed: list[float] = []
    t0 = time.monotonic()
    if key:

        def wait_for_enter() -> None:
            input()
            pressed.append(time.monotonic() - t0)

        threading.Thread(target=wait_for_enter, daemon=True).start()
        err_console.print("press Enter when you hear the stop")
    t_first = time.monotonic() - t0
    blocks = _step_while_recording(ctrl, joint, 1 if direction == "+" else -1, steps, hz, mic, meter)
    if getattr(mic, "error", None) is not None:
        fail(f"{serial_port}: {mic.error}")
    dropped = int(getattr(mic, "overflows", 0) or 0)
    if dropped:
        fail(
            f"the sound card dropped audio {dropped} time{'s' if dropped != 1 else ''} while recording (input "
            "overflow): the stop's label would not line up with the sound; nothing written: close other programs "
            "that use the sound card and record again"
        )
    samples = np.concatenate(blocks) if blocks else np.zeros(0, np.float32)
    if key:
        if not pressed:
            fail("no key press: the stop was not labelled")
        return samples, rate, pressed[0], "a key press"
    assert stop_at_step is not None
    return samples, rate, t_first + stop_at_step / hz, f"step {stop_at_step} at {hz:g} Hz"


def _step_while_recording(ctrl: Any, joint: int, sign: int, steps: int, hz: float, mic: Any, meter: Any) -> list[Any]:
    """Issue ``steps`` in bursts of 0.1 s while ``mic`` records (the meter on stderr); the blocks recorded."""
    import time

    blocks: list[Any] = []
    try:
        burst = max(1, int(hz * 0.1))
        issued = 0
        while issued < steps:
            n = min(burst, steps - issued)
            tb = time.monotonic()
            ctrl.step(joint, sign * n)
            issued += n
            for b in _drain(mic, tb + n / hz):
                blocks.append(b)
                err_console.print(CARRIAGE_RETURN, meter.feed(b).line(), sep="", end="", highlight=False)
        blocks += list(_drain(mic, time.monotonic() + 0.3))
        ctrl.stop(joint)
    finally:
        mic.stop()
        err_console.print()
    return blocks


class _SerialRecorder:
    """A serial vibration sensor read in a thread into a queue, as the microphone's callback fills one."""

    def __init__(self, port: str, sample_rate: int) -> None:
        import queue

        from ..audio.sources import AudioSourceError
        from ..audio.sources.vibration import SerialSamples

        try:
            self.src = SerialSamples(port, sample_rate=sample_rate)
        except AudioSourceError as e:
            fail(str(e))
        self._queue: queue.Queue[Any] = queue.Queue()
        self.error: Exception | None = None
        self._stopping = False

    def _read(self) -> None:
        try:
            for block in self.src.blocks():
                self._queue.put(block)
                if self._stopping:
                    return
        except Exception as e:  # noqa: BLE001 - reported in the main thread, one line
            if not self._stopping:
                self.error = e

    def start(self) -> _SerialRecorder:
        import threading

        threading.Thread(target=self._read, name="serial-sensor", daemon=True).start()
        return self

    def stop(self) -> None:
        self._stopping = True
        self.src.close()


def _drain(mic: Any, until: float) -> Iterator[Any]:
    import queue
    import time

    while True:
        left = until - time.monotonic()
        try:
            data = mic._queue.get(timeout=max(left, 0.0) + 0.01)
        except queue.Empty:
            if left <= 0:
                return
            continue
        yield data.mean(axis=1) if data.ndim == 2 else data.reshape(-1)
