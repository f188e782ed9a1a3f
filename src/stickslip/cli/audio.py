"""Audio limit switch commands: ``tune`` (from a labelled recording) and ``listen``."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from . import app
from ._common import console, err_console, fail, print_json


def _load_wav(path: Path):
    from ..audio.sources import AudioSourceError, read_wav

    try:
        return read_wav(path)
    except AudioSourceError as e:
        fail(str(e))


@app.command()
def tune(
    recording: Path = typer.Argument(
        ..., help="WAV recording: stepping, then stepping against the end stop.", metavar="REC.wav"
    ),
    stop_at: float = typer.Option(
        ..., "--stop-at", help="When the joint reached its stop, seconds from the start."
    ),
    out: Path = typer.Option(
        ..., "-o", "--out", help="Where to write the tuning (JSON: band in Hz, threshold in dB re the broadband level)."
    ),
    joint: int = typer.Option(None, "--joint", help="Joint 1, 2 or 3 the recording belongs to."),
    min_band: float = typer.Option(
        1400.0,
        "--min-band",
        help="Narrowest band considered, Hz; keep it above your highest step rate.",
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the tuning as JSON."),
) -> None:
    """Tune the audio limit switch of one joint from a labelled recording.

    Searches bands (1/6 to 1.5 octaves, at least --min-band Hz wide) for the one whose
    level when stopped (5th percentile) most exceeds its level while stepping (99.5th
    percentile), puts the threshold half-way between, checks that the tuned detector
    fires once at the stop, and saves band (Hz), threshold (dB relative to the broadband level, so a
    change of microphone gain does not move it) and latency (s).

    Example: stickslip tune joint2.wav --stop-at 4.2 --joint 2 -o joint2-tuning.json
    """
    from ..audio.tuning import TuningError
    from ..audio.tuning import tune as tune_

    if joint is not None and joint not in (1, 2, 3):
        fail(f"--joint must be 1, 2 or 3, got {joint}")
    samples, rate = _load_wav(recording)
    duration = samples.size / rate
    if not 0 < stop_at < duration:
        fail(f"--stop-at {stop_at:g} s is outside the recording (0..{duration:.3f} s)")
    try:
        tuning = tune_(samples, rate, stop_at, joint=joint, min_band_hz=min_band)
    except TuningError as e:
        fail(f"{recording}: {e}")
    try:
        tuning.save(out)
    except OSError as e:
        fail(f"cannot write {out}: {e.strerror or e}")
    if json_out:
        print_json(tuning.to_dict())
        return
    console.print(f"[bold]tuning for {recording}[/] (joint {joint if joint else '?'})")
    console.print(tuning.report(), highlight=False)
    console.print(f"saved to {out}")


@app.command()
def listen(
    recording: Path = typer.Argument(
        None, help="WAV file to listen to (or use --mic).", metavar="[REC.wav]"
    ),
    tuning_path: Path = typer.Option(
        ..., "--tuning", help="Tuning JSON written by 'stickslip tune'."
    ),
    mic: bool = typer.Option(False, "--mic", help="Listen live to the microphone until Ctrl-C."),
    device: str = typer.Option(
        None,
        "--input",
        help="Audio input device (index or name) for --mic; `python -m sounddevice` lists them.",
    ),
    json_out: bool = typer.Option(
        False,
        "--json",
        help=(
            "Print a JSON list of events: detected_at_s, onset_s (s), level_db (dB, as the tuning's threshold); "
            "with --mic one JSON object per line as they happen."
        ),
    ),
) -> None:
    """Listen for end stops in a recording (or live) with a tuned detector.

    Prints each event: when it was detected, the estimated onset of the stop (s from
    the start) and the band level (dB, in the tuning's unit).

    Examples: stickslip listen joint2.wav --tuning joint2-tuning.json --json
              stickslip listen --mic --tuning joint2-tuning.json
    """
    from ..audio.detector import StopDetector, Tuning, TuningFileError

    if mic == (recording is not None):
        fail("give either a recording REC.wav or --mic")
    try:
        tuning = Tuning.load(tuning_path)
    except TuningFileError as e:
        fail(str(e))
    except OSError as e:
        fail(f"cannot read tuning {tuning_path}: {e.strerror or e}")
    if mic:
        _listen_live(tuning, device, json_out)
        return

    from ..audio.sources import AudioSourceError, wav_blocks

    events = []
    try:
        det = None
        for block, rate in wav_blocks(recording, block=4096):
            if det is None:
                try:
                    det = StopDetector(tuning.for_sample_rate(rate))
                except ValueError as e:
                    fail(f"tuning {tuning_path} does not fit {recording} at {rate} Hz: {e}")
            events += det.feed(block)
    except AudioSourceError as e:
        fail(str(e))
    if json_out:
        print_json([e.to_dict() for e in events])
        return
    if not events:
        console.print("no end stop heard")
    for e in events:
        console.print(
            f"stop: detected at {e.detected_at_s:.4f} s, onset {e.onset_s:.4f} s, "
            f"level {e.level_db:.1f} {tuning.level_unit}",
            highlight=False,
        )


def _listen_live(tuning, device: str | None, json_out: bool) -> None:
    from ..audio.detector import StopDetector
    from ..audio.sources import AudioSourceError, Microphone

    dev: int | str | None = int(device) if device is not None and device.isdigit() else device
    mic = Microphone(sample_rate=tuning.sample_rate, block=1024, device=dev)
    det = StopDetector(tuning)
    try:
        mic.start()
    except AudioSourceError as e:
        fail(str(e))
    if not json_out:
        err_console.print(f"listening at {tuning.sample_rate} Hz; Ctrl-C to stop")
    try:
        for block in mic.blocks():
            for e in det.feed(block):
                if json_out:
                    typer.echo(json.dumps(e.to_dict()))
                else:
                    console.print(
                        f"stop: detected at {e.detected_at_s:.3f} s, onset {e.onset_s:.3f} s, "
                        f"level {e.level_db:.1f} {tuning.level_unit}",
                        highlight=False,
                    )
    except KeyboardInterrupt:
        pass
    except AudioSourceError as e:
        fail(str(e))
    finally:
        mic.stop()
