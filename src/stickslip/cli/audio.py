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
        ..., "-o", "--out", help="Where to write the tuning (JSON: sub-band edges in Hz, the stop's signature in dB)."
    ),
    joint: int = typer.Option(None, "--joint", help="Joint 1, 2 or 3 the recording belongs to."),
    min_band: float = typer.Option(
        1400.0,
        "--min-band",
        help="--method band only: narrowest band considered, Hz; keep it above your highest step rate.",
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
    json_out: bool = typer.Option(False, "--json", help="Print the tuning as JSON."),
) -> None:
    """Tune the audio limit switch of one joint from a labelled recording.

    Learns the stepping sound's spectral template (sub-bands over the band where stepping
    is heard, never above 0.42 of the sample rate) and the end stop's signature: how
    much each sub-band changes at the stop, in dB (louder, quieter, duller or brighter).
    Candidates are scored on their worst stepping frames and verified best first on the
    recording; a label that disagrees with where the sound changes is a warning, one
    where nothing changes is refused. The self-check reports the expected false alarms
    per hour with interference added, and the latency.

    Example: stickslip tune joint2.wav --stop-at 4.2 --joint 2 -o joint2-tuning.json
    """
    from ..audio.tuning import TuningError
    from ..audio.tuning import tune as tune_
    from ..audio.tuning import tune_band

    if joint is not None and joint not in (1, 2, 3):
        fail(f"--joint must be 1, 2 or 3, got {joint}")
    if method not in ("template", "band"):
        fail(f"--method must be 'template' or 'band', got {method!r}")
    samples, rate = _load_wav(recording)
    duration = samples.size / rate
    if not 0 < stop_at < duration:
        fail(f"--stop-at {stop_at:g} s is outside the recording (0..{duration:.3f} s)")
    try:
        if method == "band":
            tuning = tune_band(samples, rate, stop_at, joint=joint, min_band_hz=min_band)
        else:
            tuning = tune_(samples, rate, stop_at, joint=joint, self_check=self_check)
    except TuningError as e:
        fail(f"{recording}: {e}")
    try:
        tuning.save(out)
    except OSError as e:
        fail(f"cannot write {out}: {e.strerror or e}")
    for w in (tuning.checks or {}).get("warnings", []):
        err_console.print(f"warning: {w}", highlight=False, soft_wrap=True)
    if json_out:
        print_json(tuning.to_dict())
        return
    console.print(f"[bold]tuning for {recording}[/] (joint {joint if joint else '?'})")
    console.print(tuning.report(), highlight=False, soft_wrap=True)
    console.print(f"saved to {out}", soft_wrap=True)


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

    from ..audio.guard import block_problem

    if tuning.method == "band":
        err_console.print(
            f"note: {tuning_path} is a version-1 band-power tuning; re-tune with 'stickslip tune' for the "
            "spectral-template detector (it rejects knocks and hears quieter or duller stops)",
            highlight=False,
        )
    events = []
    problems: set[str | None] = set()
    try:
        det = None
        for block, rate in wav_blocks(recording, block=1 << 16):
            if det is None:
                try:
                    det = StopDetector(tuning.for_sample_rate(rate))
                except ValueError as e:
                    fail(f"tuning {tuning_path} does not fit {recording} at {rate} Hz: {e}")
            problems.add(block_problem(block))
            events += det.feed(block)
    except AudioSourceError as e:
        fail(str(e))
    if problems and None not in problems:
        err_console.print(f"warning: {recording} carries no signal ({', '.join(sorted(p for p in problems if p))})")
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
