"""Every command's --help read as a user who trusts it: what it names exists, what it takes is used (audit40)."""

import json

from synth import paper_table
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.measurements import measurements_to_csv

runner = CliRunner()


def _bad(result, *words, code=2):
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output and "Traceback" not in result.stderr
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for w in words:
        assert w in result.stderr, result.stderr


def test_fit_with_an_unknown_model_family_is_one_line_naming_the_known_ones(tmp_path):
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    _bad(runner.invoke(app, ["fit", str(meas), "--model", "foo", "--json"]), "no model family 'foo'", "torque2")


def test_the_traverse_ids_delete_and_exclude_take_are_where_their_help_says(tmp_path):
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    db = str(tmp_path / "s.db")
    r = runner.invoke(app, ["import", str(meas), "--device", "sim://", "--db", db, "--json"])
    assert r.exit_code == 0, r.output
    imported = json.loads(r.stdout)["ids"]
    assert len(imported) == 14
    r = runner.invoke(app, ["history", "--db", db, "--json"])
    assert r.exit_code == 0, r.output
    (entry,) = json.loads(r.stdout)
    assert sorted(entry["traverse_ids"]) == sorted(imported)
    first = str(entry["traverse_ids"][0])
    r = runner.invoke(app, ["exclude", "-t", first, "--reason", "cable snagged", "--db", db])
    assert r.exit_code == 0 and "excluded 1 traverse(s)" in r.stdout, r.output
    (entry,) = json.loads(runner.invoke(app, ["history", "--db", db, "--json"]).stdout)
    assert entry["excluded"] == 1 and len(entry["traverse_ids"]) == 14  # an excluded traverse keeps its id listed
    r = runner.invoke(app, ["delete", "-t", first, "--yes", "--db", db, "--json"])
    assert r.exit_code == 0 and json.loads(r.stdout)["traverses"] == 1, r.output
    for cmd in ("delete", "exclude"):
        text = runner.invoke(app, [cmd, "--help"], env={"COLUMNS": "200"}).stdout
        assert "history --json" in text and "stickslip export" not in text


def test_delete_without_yes_at_the_end_of_the_input_is_declined_exit_1_not_interrupted(tmp_path):
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    db = str(tmp_path / "s.db")
    assert runner.invoke(app, ["import", str(meas), "-d", "sim://", "--db", db]).exit_code == 0
    r = runner.invoke(app, ["delete", "--day", "2026-11-22", "--db", db, "--json"], input="")
    assert r.exit_code == 1, r.output  # docs/cli.md: 1 = declined at a confirmation; 130 is Ctrl-C
    assert r.stdout == "" and "interrupted" not in r.stderr
    assert "delete 14 traverse(s) of day 2026-11-22" in r.stderr and "nothing deleted (not confirmed" in r.stderr
    r = runner.invoke(app, ["delete", "--day", "2026-11-22", "--db", db, "--json"], input="y\n")
    assert r.exit_code == 0 and json.loads(r.stdout)["traverses"] == 14, r.output


def test_record_refuses_a_real_controllers_options_on_the_simulator_where_they_did_nothing(tmp_path):
    wav = tmp_path / "j2.wav"
    sim = ["record", str(wav), "--joint", "2", "--device", "sim://?seed=3"]
    _bad(runner.invoke(app, [*sim, "--steps", "5000", "--stop-at-step", "3000", "--json"]), "--steps, --stop-at-step")
    _bad(runner.invoke(app, [*sim, "--key"]), "--key: a real controller option")
    _bad(runner.invoke(app, [*sim, "--input", "3"]), "--input")
    assert not wav.exists()
    r = runner.invoke(app, [*sim, "--before", "1", "--json"])  # the simulator's own options still work
    assert r.exit_code == 0, r.output
    assert abs(json.loads(r.stdout)["label"]["stop_at_s"] - 1.0) < 0.05


def test_record_refuses_the_simulators_before_and_after_on_a_real_controller(tmp_path, monkeypatch):
    import stickslip.devices as devices

    class _Ctrl:
        def close(self) -> None:
            pass

    monkeypatch.setattr(devices, "open_device", lambda url: _Ctrl())
    r = runner.invoke(app, ["record", str(tmp_path / "r.wav"), "--joint", "2", "--device", "mm3a:///dev/fake",
                            "--steps", "400", "--stop-at-step", "300", "--before", "1"])  # fmt: skip
    _bad(r, "--before and --after place the simulator's joint")


def test_traverse_refuses_a_sound_card_input_on_the_simulator_which_hears_itself(tmp_path):
    from tuned import tune  # the session's kept tunings (tests/support/tuned.py)

    from stickslip.sim.arm import SimulatedMM3A

    samples, rate, stop_at = SimulatedMM3A(seed=4, day="2026-11-20").labelled_recording(3, "+")
    tuning = tmp_path / "t3.json"
    tune(samples, rate, stop_at, joint=3).save(tuning)
    r = runner.invoke(app, ["traverse", "-j", "3", "--direction", "+", "--tuning", str(tuning), "--input", "3",
                            "--device", "sim://?seed=3", "--no-db", "--json"])  # fmt: skip
    _bad(r, "--input 3: a sound card listens to a real controller; the simulator hears itself")


def test_calibrate_refuses_drift_without_the_prior_it_belongs_to(tmp_path):
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    _bad(runner.invoke(app, ["calibrate", str(meas), "--drift", "0.3", "--json"]), "--drift", "--prior")
    prior = tmp_path / "prior.json"
    assert runner.invoke(app, ["calibrate", str(meas), "-o", str(prior)]).exit_code == 0
    r = runner.invoke(app, ["calibrate", str(meas), "--prior", str(prior), "--drift", "0", "--json"])
    _bad(r, "--drift must be above 0")  # named as the option, as its help says: above 0
    import dataclasses

    today = tmp_path / "today.csv"  # steps 10 % shorter than the prior's: how far the update goes depends on --drift
    today.write_text(measurements_to_csv([dataclasses.replace(t, steps=round(t.steps / 0.9)) for t in paper_table()]))
    runs = {}
    for drift in ([], ["--drift", "0.15"], ["--drift", "0.5"]):
        r = runner.invoke(app, ["calibrate", str(today), "--prior", str(prior), *drift, "--json"])
        assert r.exit_code == 0, r.output
        runs[tuple(drift)] = json.loads(r.stdout)["parameters"]
    assert runs[()] == runs[("--drift", "0.15")] != runs[("--drift", "0.5")]  # the default is 0.15, and it is used


def test_the_reference_shows_what_help_shows_the_metavar_unit_and_no_default_help_hides():
    from stickslip.cli.reference import render

    page = render()
    serve = page.split("## `stickslip serve`")[1].split("## `stickslip history`")[0]
    assert "| `--max-age` `<days>` | option | Warn when the calibration is more than this many days old" in serve
    assert "| `--tuning` `J=FILE` | option |" in serve and "`[]`" not in page  # a Python list is no default
    assert "| `--geometry` `OFFSET,LENGTH` | option | OFFSET,LENGTH of the arm, lengths with their units" in serve
    assert "| `--direction` `<+\\|->` | option |" in page  # a | inside a cell is escaped: the table keeps its columns
    for line in page.splitlines():
        if line.startswith("| `--"):
            assert line.replace("\\|", "").count("|") == 4, line


def _kept(db, device="sim://"):
    r = runner.invoke(app, ["where", "-d", device, "--db", str(db), "--offline", "--json"])
    assert r.exit_code == 0, r.output
    return [j["source"] for j in json.loads(r.stdout)["joints"]]


def test_a_camera_that_does_not_open_leaves_the_kept_positions_as_they_were(tmp_path):
    db = tmp_path / "s.db"
    assert runner.invoke(app, ["where", "-d", "sim://", "--db", str(db), "--set", "3=min"]).exit_code == 0
    r = runner.invoke(app, ["camera", "calibrate", "-d", "sim://", "--camera", "simcam://?pixel=-1um", "--db", str(db),
                            "--json"])  # fmt: skip
    _bad(r, "pixel='-1um'")
    assert _kept(db) == ["default", "default", "set"]  # nothing stepped: no joint uncertain


def test_a_traverse_refused_before_it_moves_leaves_the_kept_position_as_it_was(tmp_path):
    import pytest

    from stickslip.devices.base import DeviceError
    from stickslip.kinematics import Pose
    from stickslip.procedures.session import TraverseRequest, traverse
    from stickslip.storage import Store

    def no_device(url):
        raise DeviceError(f"{url}: cannot open serial port")

    db = tmp_path / "s.db"
    assert runner.invoke(app, ["where", "-d", "sim://", "--db", str(db), "--set", "3=min"]).exit_code == 0
    pose = Pose(0.0, -1.5707963, 0.0, 0.0, 0.0)
    with Store.open(db) as store:
        with pytest.raises(ValueError, match="burst_steps = 0"):
            traverse(store, TraverseRequest("sim://", 3, "+", pose, "2026-11-22", None, burst=0))  # type: ignore
        with pytest.raises(DeviceError, match="cannot open serial port"):
            traverse(store, TraverseRequest("sim://", 3, "+", pose, "2026-11-22", None), opener=no_device)  # type: ignore
    assert _kept(db) == ["default", "default", "set"]  # nothing moved: joint 3 is still at its set stop
    _bad(runner.invoke(app, ["traverse", "-j", "3", "--direction", "+", "--tuning", str(tmp_path / "t.json"),
                             "--burst", "0", "--db", str(db)]), "--burst")  # fmt: skip


def test_a_sound_card_that_does_not_open_leaves_the_kept_position_as_it_was(tmp_path, monkeypatch):
    # audit51: PortAudio missing, no step sent, yet joint 3 was kept "uncertain, a traverse did not finish" (0-12 mm)
    import pytest

    from stickslip.audio import sources
    from stickslip.audio.detector import Tuning
    from stickslip.audio.sources.files import AudioSourceError
    from stickslip.kinematics import Pose
    from stickslip.procedures.session import TraverseRequest, traverse
    from stickslip.storage import Store

    class Console:  # a real controller: no microphone of its own, so the traverse listens to a sound card
        def frequency(self, joint):
            return 1000.0

        def close(self):
            pass

    class NoCard:
        def __init__(self, **kw):
            pass

        def start(self):
            raise AudioSourceError("PortAudio is not installed; apt-get install libportaudio2")

    monkeypatch.setattr(sources, "Microphone", NoCard)
    db = tmp_path / "s.db"
    assert runner.invoke(app, ["where", "-d", "sim://", "--db", str(db), "--set", "3=min"]).exit_code == 0
    request = TraverseRequest("sim://", 3, "+", Pose(0.0, -1.5707963, 0.0, 0.0, 0.0), "2026-11-22",
                              Tuning(band_hz=(5600, 7100), threshold_db=-40.0), audio_input=2)
    with Store.open(db) as store, pytest.raises(AudioSourceError, match="PortAudio"):
        traverse(store, request, opener=lambda _url: Console())  # type: ignore[arg-type,return-value]
    assert _kept(db) == ["default", "default", "set"]  # before: joint 3 "uncertain" though nothing moved


def test_jog_without_a_terminal_prints_its_one_error_and_no_warning_ahead_of_it(tmp_path):
    meas, cal = tmp_path / "meas.csv", tmp_path / "cal.json"
    meas.write_text(measurements_to_csv(paper_table()))
    assert runner.invoke(app, ["calibrate", str(meas), "--day", "2026-01-01", "-o", str(cal)]).exit_code == 0
    r = runner.invoke(app, ["jog", "-c", str(cal), "-d", "sim://", "--db", str(tmp_path / "s.db")])
    _bad(r, "jog needs a terminal")  # before: the joint-1 and calibration-age warnings came first, then the error


def test_traverse_writes_its_result_alone_on_stdout_no_progress_bar_residue(tmp_path):
    from tuned import tune

    from stickslip.sim.arm import SimulatedMM3A

    samples, rate, stop_at = SimulatedMM3A(seed=4, day="2026-11-20").labelled_recording(3, "+")
    tuning = tmp_path / "t3.json"
    tune(samples, rate, stop_at, joint=3).save(tuning)
    r = runner.invoke(app, ["traverse", "-j", "3", "--direction", "+", "--tuning", str(tuning), "--no-db",
                            "--device", "sim://?seed=4&day=2026-11-20"])  # fmt: skip
    assert r.exit_code == 0, r.output
    assert r.stdout.splitlines()[0].startswith("joint 3+: ") and len(r.stdout.splitlines()) == 1, repr(r.stdout)


def test_calibrate_prior_says_what_its_plus_minus_is(tmp_path):
    import dataclasses

    meas, prior, today = tmp_path / "meas.csv", tmp_path / "prior.json", tmp_path / "today.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    today.write_text(measurements_to_csv([dataclasses.replace(t, steps=round(t.steps / 0.9)) for t in paper_table()]))
    assert runner.invoke(app, ["calibrate", str(meas), "-o", str(prior)]).exit_code == 0
    r = runner.invoke(app, ["calibrate", str(today), "--prior", str(prior)], env={"COLUMNS": "250"})
    assert r.exit_code == 0, r.output
    scale = [ln for ln in r.stdout.splitlines() if "step scale x" in ln]
    assert scale and all("(σ " in ln and "±" not in ln for ln in scale), scale  # docs/cli.md: a ± says what it is


def test_a_live_camera_that_does_not_open_is_one_error_line_without_opencvs_own_warnings(tmp_path):
    import os
    import subprocess
    import sys

    import pytest

    pytest.importorskip("cv2")
    env = {**os.environ, "STICKSLIP_DB": str(tmp_path / "s.db")}
    code = "import sys; from stickslip.cli import app; sys.argv[0] = 'stickslip'; app()"
    r = subprocess.run(
        [sys.executable, "-c", code, "camera", "grab", "--camera", "opencv://99?pixel=1um",
         "-o", str(tmp_path / "g.png"), "--json"],
        capture_output=True, env=env, timeout=60, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert r.returncode == 2 and r.stdout == b"", r
    lines = r.stderr.decode().splitlines()
    assert lines == ["error: camera 99 does not open (not connected, or in use by another program)"], lines


def test_camera_calibrates_view_options_say_they_are_angles_their_range_and_reference():
    from stickslip.cli.reference import render

    page = render().split("## `stickslip camera calibrate`")[1].split("## `stickslip camera grab`")[0]
    rows = {ln.split("|")[1].strip(): ln.split("|")[3] for ln in page.splitlines() if ln.startswith("| `--view")}
    assert "an angle in 0-90deg" in rows["`--view-tilt`"]
    assert "an angle from the world x axis towards y" in rows["`--view-azimuth`"]
    assert "an angle" in rows["`--view-roll`"]
    r = runner.invoke(app, ["camera", "calibrate", "--camera", "simcam://?pixel=1um", "--view-tilt", "91deg"])
    _bad(r, "view tilt = 91 deg must be in [0, 90] deg")  # the range the help says is the one checked


def test_a_default_of_0_is_shown_in_help_and_the_reference_as_any_other():
    from stickslip.cli.reference import render

    text = " ".join(runner.invoke(app, ["demo", "--help"], env={"COLUMNS": "120"}).stdout.split())
    assert "Simulator seed: drift of the true parameters, step noise, room sound. [default: 0]" in text  # 0 == False
    assert "room sound. (default: `0`) |" in render()


def test_calibrate_check_help_says_the_paper_procedure_alone_has_nothing_to_check(tmp_path):
    from stickslip.cli.reference import render

    page = render().split("## `stickslip calibrate`")[1].split("## `stickslip fit`")[0]
    assert "Example: stickslip calibrate day1-and-sweep.csv --check check1.csv" in page
    assert "more traverses than the paper's 14 poses: the paper's procedure alone has no intervals to scale" in page
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))  # the paper's 14 poses exactly
    import dataclasses

    check = tmp_path / "check.csv"  # new poses: psi 0.3 rad, which none of the paper's has
    check.write_text(measurements_to_csv([dataclasses.replace(t, psi=0.3) for t in paper_table()]))
    r = runner.invoke(app, ["calibrate", str(meas), "--check", str(check), "--json"])
    _bad(r, "can check this calibration")  # as the help says: refused


def test_listen_refuses_input_without_mic_where_it_was_taken_and_not_used(tmp_path):
    import numpy as np

    from stickslip.audio.sources import write_wav

    wav = tmp_path / "r.wav"
    write_wav(wav, np.zeros(4800, np.float32), 48_000)
    _bad(runner.invoke(app, ["listen", str(wav), "--tuning", str(tmp_path / "t.json"), "--input", "3", "--json"]),
         "--input picks the sound card --mic listens to")  # fmt: skip


def test_reach_segment_help_says_the_range_that_is_checked(tmp_path):
    from stickslip.cli.reference import render

    assert "| `--segment` | option | Longest segment of the line, a length from 10nm to 1mm. (default: `10um`) |" in (
        render()
    )
    meas, cal = tmp_path / "meas.csv", tmp_path / "cal.json"
    meas.write_text(measurements_to_csv(paper_table()))
    assert runner.invoke(app, ["calibrate", str(meas), "-o", str(cal)]).exit_code == 0
    reach = ["reach", "-c", str(cal), "-d", "sim://", "--by", "1um,0,0", "--dry-run", "--db", str(tmp_path / "s.db")]
    _bad(runner.invoke(app, [*reach, "--segment", "9nm", "--json"]), "between 10 nm and 1 mm")
    _bad(runner.invoke(app, [*reach, "--segment", "1.1mm", "--json"]), "between 10 nm and 1 mm")
    for ok in ("10nm", "1mm"):
        r = runner.invoke(app, [*reach, "--segment", ok, "--json"])
        assert r.exit_code == 0, r.output


def test_the_reference_shows_the_range_help_shows_and_the_command_checks():
    from stickslip.cli.reference import render

    page = render()
    assert "| `--hold` | option | Seconds a direction key keeps moving without a repeat (0: until space). " \
           "(range: 0 to 10) (default: `0.5`) |" in page  # fmt: skip
    text = " ".join(runner.invoke(app, ["jog", "--help"], env={"COLUMNS": "120"}).stdout.split())
    assert "(0: until space). [0 to 10; default: 0.5]" in text
    _bad(runner.invoke(app, ["jog", "--hold", "11"]), "--hold")


def test_calibrates_conditions_are_refused_naming_the_option_with_the_recorded_range(tmp_path):
    import typer.main

    from stickslip.calibration.result import _CONDITION_RANGES

    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    r = runner.invoke(app, ["calibrate", str(meas), "--frequency", "-5", "--json"])
    _bad(r, "'--frequency'", "0.001")  # was: conditions.frequency_hz must be ...
    options = {p.name: p for p in typer.main.get_command(app).get_command(None, "calibrate").params}
    for name, field in (("frequency", "frequency_hz"), ("amplitude", "amplitude_v"), ("temperature", "temperature_c")):
        assert (options[name].min, options[name].max) == _CONDITION_RANGES[field]


def test_confirm_s_and_rate_help_say_the_ranges_that_are_checked(tmp_path):
    from stickslip.cli.reference import render

    page = render()
    for cmd in ("demo", "traverse", "listen"):
        section = page.split(f"## `stickslip {cmd}`")[1].split("\n## ")[0]
        (row,) = [ln for ln in section.splitlines() if ln.startswith("| `--confirm-s`")]
        assert "0-5 s" in row, row
    for cmd in ("tune", "listen"):
        section = page.split(f"## `stickslip {cmd}`")[1].split("\n## ")[0]
        (row,) = [ln for ln in section.splitlines() if ln.startswith("| `--rate`")]
        assert "1-100000 Hz" in row, row
    _bad(runner.invoke(app, ["demo", "--confirm-s", "5.1", "--json"]), "outside [0, 5]")
    _bad(runner.invoke(app, ["listen", str(tmp_path / "x.wav"), "--tuning", "t.json", "--rate", "100001"]), "1-100000")


def test_move_to_max_is_planned_to_the_stops_position_as_its_help_says_not_referenced(tmp_path):
    from stickslip.cli.reference import render

    assert "'min'/'max' = an end stop's position, planned as any other (not driven into the stop" in render()
    meas, cal, db = tmp_path / "meas.csv", tmp_path / "cal.json", str(tmp_path / "s.db")
    meas.write_text(measurements_to_csv(paper_table()))
    assert runner.invoke(app, ["calibrate", str(meas), "-o", str(cal)]).exit_code == 0
    r = runner.invoke(app, ["move", "-d", "sim://", "-c", str(cal), "-j", "3", "--to", "max", "--db", db, "--json"])
    assert r.exit_code == 0, r.output
    (j3,) = [j for j in json.loads(runner.invoke(app, ["where", "-d", "sim://", "--db", db, "--offline",
                                                       "--json"]).stdout)["joints"] if j["joint"] == 3]  # fmt: skip
    assert j3["source"] == "dead-reckoned" and j3["q"] == 0.012 and j3["sd"] > 1e-4  # planned (σ 0.9 mm)


def test_tunes_sample_rate_help_names_no_option_tune_lacks_and_says_the_checked_range(tmp_path):
    from stickslip.cli.reference import render

    page = render()
    tune = page.split("## `stickslip tune`")[1].split("\n## ")[0]
    (row,) = [ln for ln in tune.splitlines() if ln.startswith("| `--sample-rate`")]
    assert "--serial" not in row and "the tuning's" not in row and "1000-1000000 Hz" in row, row
    assert "| `--serial`" not in tune  # the option the old text named
    listen = page.split("## `stickslip listen`")[1].split("\n## ")[0]
    assert "1000-1000000 Hz" in [ln for ln in listen.splitlines() if ln.startswith("| `--sample-rate`")][0]
    csv = tmp_path / "a.csv"
    csv.write_text("0.1\n0.2\n")
    r = runner.invoke(app, ["tune", str(csv), "--stop-at", "1", "--sample-rate", "999", "-o", str(tmp_path / "t.json")])
    _bad(r, "sample rate 999 Hz is outside 1000-1000000 Hz")


def test_step_sizes_of_a_joint_the_prior_lacks_are_refused_with_a_way_that_works(tmp_path):
    from stickslip.measurements import StepSize, write_step_sizes

    meas, prior, steps = tmp_path / "meas.csv", tmp_path / "prior.json", tmp_path / "steps.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    assert runner.invoke(app, ["calibrate", str(meas), "-o", str(prior)]).exit_code == 0
    pose = dict(q1=0.0, q2=-1.5707963267948966, q3=0.0, theta=0.0, psi=0.0)
    rows = [StepSize(day="2026-11-22", joint=j, direction=d, gamma=g, sigma=g * 0.004, steps=87, method="camera",
                     **pose) for j, g in ((3, 9.7e-7), (1, 4.8e-5)) for d in "+-"]  # fmt: skip
    write_step_sizes(steps, rows)  # what camera calibrate writes with its default --joints 3,1,2 at this pose
    cmd = ["calibrate", "--prior", str(prior), "--step-sizes", str(steps), "--json"]
    _bad(runner.invoke(app, cmd), "no model for joint 1+, joint 1-", "camera calibrate --joints 3,2")
    write_step_sizes(steps, [r for r in rows if r.joint != 1])  # as the message says: it works
    assert runner.invoke(app, cmd).exit_code == 0
    help_text = runner.invoke(app, ["calibrate", "--help"], env={"COLUMNS": "120"}).stdout
    assert "measure with camera calibrate --joints 3,2" in " ".join(help_text.split())


def test_calibrates_notes_wrap_at_spaces_with_later_lines_indented_as_results_do(tmp_path):
    import dataclasses

    meas = tmp_path / "meas.csv"  # more than the paper's poses: the families' notes
    meas.write_text(measurements_to_csv([*paper_table(), *(dataclasses.replace(t, psi=0.3) for t in paper_table())]))
    from stickslip.cli._output import console

    r = runner.invoke(app, ["calibrate", str(meas)], env={"COLUMNS": "60"})
    assert r.exit_code == 0, r.output
    width = console.width  # the width it printed at (60, or what an earlier test left the shared console at)
    notes = json.loads(runner.invoke(app, ["calibrate", str(meas), "--json"]).stdout)["provenance"]["notes"]
    lines = r.stdout.splitlines()
    starts = [i for i, ln in enumerate(lines) if ln.startswith("note: ")]
    assert len(starts) == len(notes) and any(len(n) + 6 > width for n in notes)
    for i, note in zip(starts, notes, strict=True):
        k = i + 1
        while k < len(lines) and lines[k].startswith("  "):
            k += 1
        assert all(len(ln) <= width for ln in lines[i:k])  # within the width, later lines indented
        assert " ".join(" ".join(lines[i:k]).split()) == " ".join(f"note: {note}".split())  # no word cut or lost


def test_where_says_a_kept_position_assumes_nothing_else_moved_the_arm():
    """The arms have no sensors stickslip reads: a move by the vendor's software between commands, or another
    controller under the same URL, cannot be told; `where` (and docs/cli.md) must say so and what to do (audit57)."""
    from stickslip.cli.reference import render

    r = runner.invoke(app, ["where", "--help"], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    text = " ".join(r.stdout.replace("│", " ").split())
    page = " ".join(render().split("## `stickslip where`")[1].split("## `stickslip reach`")[0].split())
    for said in (text, page):
        assert "The positions are kept, not measured" in said
        assert "reference the joints again (--set): stickslip cannot tell" in said
        assert "another controller or arm was connected under this URL" in said
        assert "a SmarAct MCS2 says its serial number, an MCS its system id" in said  # those are compared (ident59)
        assert "/dev/serial/by-id/" in said
