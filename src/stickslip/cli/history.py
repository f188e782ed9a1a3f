"""History and analysis commands: history, export, import, anova, fit, report.

The database is the embedded SQLite file of :mod:`stickslip.storage` (``--db PATH``,
else ``$STICKSLIP_DB``, else the config file's, else the user's data directory).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer
from rich.table import Table

from ..devices.base import redact_url
from . import app
from ._common import (
    console,
    db_option,
    fail,
    open_store,
    print_json,
    read_table,
    say,
    user_errors,
    warn,
    warn_later,
)
from ._output import err_console, styled, visible

if TYPE_CHECKING:
    from ..analysis import AnovaResult
    from ..measurements import Traverse



def _traverses_from(
    meas: Path | None, db: str | None, device: str | None, day: str | None, checked: bool = False
) -> tuple[list[Traverse], str]:
    """Traverses from a CSV file, or else from the database (``checked``: a stored one a fit refuses is named by
    its id)."""
    if meas is not None:
        ts = read_table(meas)
        if day is not None:
            ts = [t for t in ts if t.day == day]
            if not ts:
                fail(f"{meas}: no traverses on day {day!r}")
        return ts, str(meas)
    from ..measurements import TableError, check_traverses

    with open_store(db, must_exist=True) as st:
        ts = st.traverses(device=device, day=day)
        where = f"the database {st.path}"
        try:
            if checked:
                check_traverses(ts, limit=1)  # what a fit checks, naming a traverse by its place, not its id
        except TableError:
            fail(_stored_refusal(st, device, day, None))
    if not ts:
        dev_text = f"device {redact_url(device)}" if device else ""
        what = " and ".join(x for x in (dev_text, f"day {day}" if day else "") if x)
        fail(f"no traverses in {where}{' for ' + what if what else ''}: pass MEAS.csv or import one first")
    return ts, where


# ---------------------------------------------------------------- history / export / import


@app.command()
def history(
    device: str | None = typer.Option(None, "--device", "-d", help="Only this device URL, e.g. sim://"),
    db: str | None = db_option(),
    json_out: bool = typer.Option(
        False, "--json", help="Print a JSON list, one object per device and day, with its traverse_ids."
    ),
) -> None:
    """Show stored sessions: traverses per day and joint, and calibrations made.

    With --json each device and day also lists its traverse_ids (excluded ones too): the ids
    that exclude and delete take.

    Example: [bold]stickslip history --device sim://[/]
    """
    with open_store(db, must_exist=True) as st:
        entries = st.history(device)
        path = st.path
        if json_out:  # the ids exclude -t and delete -t take (export's table has none)
            for e in entries:
                e["traverse_ids"] = st.traverse_ids(device=e["device"], day=e["day"])
    if json_out:
        print_json(entries)
        return
    if not entries:
        say(f"no sessions stored in {path}" + (f" for device {redact_url(device)}" if device else ""), keep=(path,))
        return
    say(f"stickslip history of {path}", keep=(path,))
    for dev in dict.fromkeys(e["device"] for e in entries):  # one table per device: a URL is never folded
        say(f"device {dev}")
        table = Table(pad_edge=False)
        table.add_column("day", no_wrap=True)
        table.add_column("n", justify="right")
        table.add_column("by joint")
        table.add_column("measured (UTC)")
        table.add_column("calibrations")
        for e in (e for e in entries if e["device"] == dev):
            span = ""
            if e["first_measured_at"]:
                span = f"{e['first_measured_at'][11:16]}-{e['last_measured_at'][11:16]}"
                if e["first_measured_at"][:10] != e["day"]:
                    span = f"{e['first_measured_at'][:10]} {span}"
            cals = ", ".join(f"#{c['id']} {c['method']}" for c in e["calibrations"]) or "-"
            by = " ".join(f"{k}:{v}" for k, v in sorted(e["by_joint"].items()))
            n = str(e["traverses"]) + (f" (+{e['excluded']} excluded)" if e.get("excluded") else "")
            table.add_row(e["day"], n, by, span, cals)
        console.print(table)
    say("a calibration #N: stickslip show N (or show N -o cal.json to use it with -c)")


@app.command()
def export(
    out: Path = typer.Option(..., "-o", "--output", help="Measurement table to write (CSV, SI units)."),
    day: str | None = typer.Option(None, "--day", help="Only this session day (e.g. 2026-11-21); default all."),
    device: str | None = typer.Option(None, "--device", "-d", help="Only this device URL, e.g. sim://"),
    joint: int | None = typer.Option(None, "--joint", "-j", help="Only this joint (1, 2 or 3)."),
    db: str | None = db_option(),
    json_out: bool = typer.Option(
        False, "--json", help="Write a history file (JSON Lines) instead: every traverse, excluded ones too, with "
        "how, source, measured_at and the exclusion's reason; import reads it back as the same record.",
    ),
) -> None:
    """Write stored traverses to a measurement table (CSV, SI units).

    The table holds the traverses used in analyses, the columns of the table contract
    only. To move a history to another database as the same record (how and when each
    traverse was measured, excluded ones with their reasons) write --json and import
    that (docs/storage.md).

    Example: [bold]stickslip export --day 2026-11-21 -o meas.csv[/]
    """
    import itertools
    from collections.abc import Iterator

    from ..measurements import TableError, write_measurements
    from ..measurements.history_file import write_history

    if joint is not None and joint not in (1, 2, 3):
        fail(f"--joint must be 1, 2 or 3, got {joint}")
    with open_store(db, must_exist=True) as st:
        if json_out:  # streamed too; excluded rows included, each with its provenance
            records = st.iter_provenance(device=device, day=day, joint=joint)
            head = next(records, None)
            if head is None:
                fail(_no_match(st, device, day, joint))
            with user_errors():
                n = write_history(out, itertools.chain([head], records))
            say(f"wrote {n} traverses with their provenance to {out}", keep=(out,))
            return
        rows = st.iter_traverses(device=device, day=day, joint=joint)  # streamed: any size in bounded memory
        first = next(rows, None)
        if first is None:
            fail(_no_match(st, device, day, joint))
        count = [0]

        def counted(it: Iterator[Traverse]) -> Iterator[Traverse]:
            for t in it:
                count[0] += 1
                yield t

        with user_errors():
            try:
                write_measurements(out, counted(itertools.chain([first], rows)))
            except TableError:
                fail(_stored_refusal(st, device, day, joint, " (nothing written)"))
    say(f"wrote {count[0]} traverses to {out}", keep=(out,))


def _stored_refusal(st: Any, device: str | None, day: str | None, joint: int | None, end: str = "") -> str:
    """Which stored traverses no table can hold (a row stored before such values were refused: q3 = 5, a tilt of
    4 rad), by their ids, and how to go on. The checks name a traverse by its place in a list from 0, which read as
    a stored id: 'traverse 1' was the 2nd row, and `delete -t 1` removed another."""
    from ..measurements import HEADER, TableError, Traverse, check_traverses

    said: list[str] = []
    for r in st.traverse_records(device=device, day=day, joint=joint):
        try:
            check_traverses([Traverse(*(r[c] for c in HEADER))])
        except TableError as e:
            said += [f"stored traverse {r['id']} ({r['device']}, {r['day']}): {p.removeprefix('traverse 0: ')}"
                     for p in e.problems]
        if len(said) >= 5:
            break
    return ("; ".join(said[:5]) + ": stored before such a value was refused, no fit or table takes it; leave it "
            "out with `stickslip exclude -t ID --reason ...` (kept, with its reason) or remove it with "
            f"`stickslip delete -t ID`, then run this again{end}")


def _no_match(st: Any, device: str | None, day: str | None, joint: int | None) -> str:
    """Why ``export`` found nothing: what was asked, and what is stored (days, or the devices with traverses)."""
    asked = [a for a in (f"device {redact_url(device)}" if device else "", f"day {day!r}" if day else "",
                         f"joint {joint}" if joint else "") if a]
    what = "no traverses match" + (" " + ", ".join(asked) if asked else "")
    days = st.days(device)
    if days:
        return f"{what} (stored days: {', '.join(days)})"
    stored = list(dict.fromkeys(e["device"] for e in st.history() if e["traverses"]))
    if device is None or not stored:
        return f"{what} (the database holds no traverses)"
    return (f"{what} (the devices with traverses: {', '.join(stored)}; a device is its URL without options, "
            "but a simulator's seed picks another arm)")


@app.command("import")
def import_(
    meas: Path = typer.Argument(
        ..., help="Measurement table (CSV), or a history file (export --json), to store.", show_default=False
    ),
    device: str | None = typer.Option(
        None, "--device", "-d", help="Device URL the table was measured on (required for a table: its device is "
        "a fact about it, no default guesses it), e.g. mm3a:///dev/ttyUSB0 or sim://. A history file's rows "
        "name their own device: leave it out, or give the same device.", show_default=False,
    ),
    how: str | None = typer.Option(
        None, "--how", help="How it was measured: imported (the default), audio, simulated ... (a table only: "
        "the rows of a history file keep their own).", show_default=False,
    ),
    force: bool = typer.Option(False, "--force", help="Import even if this exact file was imported before."),
    allow_duplicates: bool = typer.Option(
        False, "--allow-duplicates", help="Store rows identical to stored ones (same device, day, pose, steps)."
    ),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print the new traverse ids as JSON."),
) -> None:
    """Store a measurement table, or a history file (export --json); on any bad row nothing is stored.

    A history file's rows keep their provenance: how and when each was measured, its
    source, and excluded rows stay excluded with their reasons.

    A row identical to a stored traverse of the same device (day, pose, interval and
    steps) is taken for the same measurement stored twice, and the import is refused
    unless --allow-duplicates (a genuine repeat can take exactly as many steps).

    The rows are stored under the device's name: its URL without options or secrets (a
    simulator's seed kept), the name measuring uses, so mm3a:///COM3 and mm3a://com3 are
    one device (docs/storage.md). A history file written by export --json names each
    row's device (a history of several devices goes back to each); one written before
    2026-12-01 does not, and needs --device.

    Example: [bold]stickslip import meas.csv --device sim://[/]
    """
    from ..measurements.history_file import is_history_file
    from ..procedures.table_import import import_table
    from ..records import regular_file
    from ..storage.schema import stored_device

    with user_errors():  # a file not there is said so, before a store is made ('is a measurement table' it was not)
        regular_file(meas, "table")
    name = stored_device(device) if device is not None else None  # what the rows are stored under
    if name is None and not is_history_file(meas):  # refused before a store is made or opened
        fail(f"{meas} is a measurement table, which does not say its device: give the device it was measured on "
             "(--device URL, e.g. mm3a:///dev/ttyUSB0 or sim://)")
    with open_store(db) as st:  # the table streams through twice: any length in bounded memory
        with user_errors():  # a bad row (every one listed), a file imported before, rows stored already
            res = import_table(st, meas, device, how, force, allow_duplicates, shown_device=name)
        path = st.path
    if json_out:
        print_json({"imported": len(res.ids), "ids": res.ids, "db": str(path)})
    else:
        console.print(
            f"imported {len(res.ids)} traverses ({', '.join(res.days)}) for {name or 'the devices the file names'} "
            f"into {path}"
        )


# ---------------------------------------------------------------- exclude / delete


@app.command()
def exclude(
    traverse: list[int] = typer.Option(..., "--traverse", "-t", help="Id of a traverse (repeatable)."),
    reason: str | None = typer.Option(None, "--reason", "-r", help="Why (kept with the row), e.g. 'cable snagged'."),
    undo: bool = typer.Option(False, "--undo", help="Use the traverses again."),
    db: str | None = db_option(),
) -> None:
    """Exclude stored traverses from calibration and analyses (kept, with the reason), or --undo.

    Ids are in `stickslip history --json` (traverse_ids of each device and day) and
    `stickslip import --json`.

    Example: [bold]stickslip exclude -t 12 -t 13 --reason "arm touched the sample"[/]
    """
    if undo == (reason is not None):
        fail("give --reason TEXT to exclude, or --undo to use the traverses again")
    with open_store(db, must_exist=True) as st, user_errors():
        n = st.set_excluded(traverse, None if undo else reason)
    console.print(f"{'included' if undo else 'excluded'} {n} traverse(s)", highlight=False)



def _confirmed(question: str) -> bool:
    """Ask ``question [y/N]`` on stderr and read the answer from stdin: y or yes confirms.

    The end of the input (a script without --yes, stdin not a terminal) is no answer, so
    not confirmed (exit 1, as documented), never the "interrupted (Ctrl-C)" exit 130
    typer's confirm made of it; Ctrl-C still ends in 130.
    """
    import sys

    err_console.print(f"{question} [y/N]: ", end="", markup=False, highlight=False)
    answer = sys.stdin.readline()
    if not answer:
        err_console.print()
    return answer.strip().lower() in ("y", "yes")


@app.command()
def delete(
    traverse: list[int] = typer.Option(None, "--traverse", "-t", help="Id of a traverse to delete (repeatable)."),
    day: str | None = typer.Option(None, "--day", help="Delete every traverse of this session day."),
    device: str | None = typer.Option(None, "--device", "-d", help="With --day: only this device."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask for confirmation."),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print what was deleted as JSON."),
) -> None:
    """Delete stored traverses (by id, or a whole session day), after confirmation.

    Calibrations made from them keep their parameters; only their links to the rows go.
    Ids are in `stickslip history --json` (traverse_ids of each device and day) and
    `stickslip import --json`.

    Example: [bold]stickslip delete --day 2026-11-22 --device sim:// --yes[/]
    """
    if not traverse and day is None:
        fail("give --traverse ID (repeatable) or --day DAY")
    with open_store(db, must_exist=True) as st:
        ids = list(traverse or [])
        if day is not None:
            ids += st.traverse_ids(device=device, day=day)
            if not ids:
                fail(f"no stored traverses for day {day}" + (f" of {redact_url(device)}" if device else ""))
        what = f"{len(set(ids))} traverse(s)" + (f" of day {day}" if day else "")
        if not yes and not _confirmed(visible(f"delete {what} from {st.path}?")):
            fail("nothing deleted (not confirmed; --yes skips the question)", code=1)
        with user_errors():
            done = st.delete_traverses(ids)
        ok = st.integrity_check()
    if json_out:
        print_json({**done, "integrity": ok})
        return
    console.print(
        f"deleted {done['traverses']} traverse(s)"
        + (f"; {done['calibration_links']} calibration link(s) removed" if done["calibration_links"] else ""),
        highlight=False,
    )


@app.command()
def backup(
    out: Path = typer.Argument(..., help="The new SQLite file to copy the database into.", metavar="OUT.db"),
    db: str | None = db_option(),
) -> None:
    """Copy the whole database (traverses, calibrations, kept positions) into a new file.

    A consistent copy even while another stickslip command is running (a plain copy of
    the file can miss what SQLite still holds in its write-ahead log). Keep it, or give
    it to a colleague: every command reads it with --db OUT.db. A shared PostgreSQL
    database (--db postgresql://...) is copied into an SQLite file the same way, every
    table read at one instant: a rig's history to take home (pg_dump backs up the
    server, docs/storage.md).

    Example: stickslip backup stickslip-2026-11-22.db
    """
    from ..storage import StoreError

    with open_store(db, must_exist=True) as st, user_errors(StoreError):
        written = st.backup(out)
        n = st.count_traverses()
    say(f"copied {n} traverse(s), the calibrations and the kept positions into {written}", keep=(written,))


# ---------------------------------------------------------------- anova


@app.command()
def anova(
    meas: Path | None = typer.Argument(None, help="Measurement table (CSV); default: the database."),
    device: str | None = typer.Option(None, "--device", "-d", help="From the database: only this device."),
    alpha: float = typer.Option(0.05, "--alpha", help="Significance level, in (0, 1)."),
    two_way: bool = typer.Option(True, "--two-way/--no-two-way", help="Also the day x direction table."),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print a JSON list, one object per test."),
    show_skipped: bool = typer.Option(False, "--show-skipped", help="List every pose group that could not be tested."),
) -> None:
    """ANOVA: does the step size change from day to day, and between + and -?

    For each joint and direction: one-way ANOVA of the average step across days,
    in poses repeated on several days. For each joint and day: + against -. With
    --two-way, the day x direction table with interaction. Poses match when
    fixed joints, tilt and traversed interval agree within 1e-3 rad / 10 um.
    Every row of the table (every stored traverse) counts: two repeats that took
    the same number of steps are two measurements, not a copy.

    Example: [bold]stickslip anova meas.csv --json[/]
    """
    from ..analysis import anova as run_anova

    if not 0.0 < alpha < 1.0:
        fail(f"--alpha must be in (0, 1), got {alpha}")
    ts, where = _traverses_from(meas, db, device, None)  # each row a traverse: equal numbers are repeats, kept
    with user_errors(ImportError):
        res = run_anova(ts, alpha=alpha, two_way=two_way)
    degenerate = [t for t in res.tests if not math.isfinite(t.F)]
    if degenerate:
        warn_later(
            f"{len(degenerate)} test(s) have no spread within their groups (F undefined): identical repeats "
            "cannot show a difference; they are marked 'degenerate', not significant"
        )
    if json_out:
        rows = res.rows()
        for row, t in zip(rows, res.tests, strict=True):
            if not math.isfinite(t.F):
                row.update(F=None, p=None, significant=False, verdict="degenerate")
        print_json(rows)
        return
    console.print(f"ANOVA of the average step size, {len(ts)} traverses from {where}")
    if not res.tests:
        warn("no testable groups: a pose must be measured on several days (or both ways on one day), repeated")
    else:
        console.print(_anova_table(res, alpha))
    if show_skipped:
        for s in res.skipped:
            console.print(styled(f"skipped: {s}", "dim"))
    elif res.skipped:
        console.print(
            styled(
                f"{len(res.skipped)} pose groups could not be tested (one traverse per day or direction); "
                "--show-skipped lists them",
                "dim",
            )
        )


def _anova_table(res: AnovaResult, alpha: float) -> Table:
    """The tests as a table: what, the pose, n, F, p and the verdict at ``alpha`` (degenerate where F is undefined)."""
    from ..analysis import PoseGroup

    table = Table(pad_edge=False)
    table.add_column("test", no_wrap=True)
    table.add_column("pose", overflow="fold", ratio=1)
    table.add_column("n", justify="right", no_wrap=True)
    table.add_column("F", justify="right", no_wrap=True)
    table.add_column("p", justify="right", no_wrap=True)
    table.add_column(f"α={alpha:g}", no_wrap=True)
    for t in res.tests:
        what = {
            "day": f"days {t.joint}{t.direction}",
            "direction": f"+/- {t.joint} {t.day}",
            "two-way": f"2-way {t.joint} {t.term}",
        }[t.test]
        verdict = {"significant": "SIGNIFICANT", "not significant": "not sig."}.get(t.verdict(alpha), "undefined")
        if not math.isfinite(t.F):
            verdict = "degenerate"
        table.add_row(
            what,
            PoseGroup(t.joint, t.pose, t.interval).describe(),
            str(t.n),
            f"{t.F:.4g}" if math.isfinite(t.F) else "-",
            f"{t.p:.3g}" if math.isfinite(t.p) and math.isfinite(t.F) else "-",
            styled(verdict, "bold red") if verdict == "SIGNIFICANT" else verdict,
        )
    return table


# ---------------------------------------------------------------- fit


@app.command()
def fit(
    meas: Path | None = typer.Argument(None, help="Measurement table (CSV); default: the database."),
    out: Path | None = typer.Option(None, "-o", "--output", help="Write the calibration JSON here."),
    day: str | None = typer.Option(None, "--day", help="Only traverses of this session day."),
    device: str | None = typer.Option(None, "--device", "-d", help="From the database: only this device."),
    record: bool = typer.Option(
        False, "--record", help="Also store the calibration in the database: for the device of the traverses it "
        "fitted, or with a table for --device (then required: a table does not say which device measured it)."
    ),
    db: str | None = db_option(),
    json_out: bool = typer.Option(False, "--json", help="Print parameters and residuals as JSON."),
    model: str = typer.Option(
        "paper", "--model", help="paper (the paper's models, least squares) | auto (the model families averaged with "
        "weights from leave-one-pose-out cross-validation, docs/models.md) | a family's name."
    ),
) -> None:
    """Fit each joint's model to all rows (nonlinear least squares, with SEs).

    Traverse averages are predicted exactly (closed-form integral along the
    traverse), so long rotary traverses count as what they are. Prints every
    parameter with its standard error (nm, µrad) and the residuals per joint and
    direction.

    Example: [bold]stickslip fit meas.csv -o cal.json[/]
    """
    from ..analysis import residual_summary
    from ..calibration import CalibrationError, calibrate

    if record and meas is not None and device is None:  # before: filed under sim://, a guess (as import's was)
        fail("fit TABLE --record needs --device: the calibration is stored for the device that measured the table, "
             "and a table does not say which (e.g. -d mm3a:///dev/ttyUSB0)")
    ts, where = _traverses_from(meas, db, device, day, checked=True)
    ids: list[int] = []
    if record and meas is None:  # link the stored traverses the fit used
        with open_store(db, must_exist=True) as st:
            recs = st.traverse_records(device=device, day=day)
        devices = sorted({r["device"] for r in recs})
        if len(devices) > 1:
            fail(f"the traverses come from several devices ({', '.join(devices)}): pick one with --device")
        device = device or devices[0]
        ids = [int(r["id"]) for r in recs]
    with user_errors(CalibrationError, KeyError):  # KeyError: an unknown --model family, named
        cal = calibrate(
            ts, method="lsq" if model == "paper" else "auto", day=day, source=str(meas) if meas else where,
            model=model,
        )
    res = residual_summary(cal, ts)
    if out is not None:
        with user_errors():
            cal.save(out)
    cal_id = None
    if record:
        with open_store(db) as st:
            with user_errors():
                cal_id = st.add_calibration(cal, device=str(device), traverse_ids=ids)
    if json_out:
        print_json(
            {
                "calibration": cal.to_dict(),
                "residuals": res.rows(),
                "output": str(out) if out else None,
                "stored_id": cal_id,
            }
        )
        return
    console.print(cal.report(), highlight=False)
    console.print(res.report(), highlight=False)
    if out is not None:
        say(f"wrote {out}", keep=(out,))
    if cal_id is not None:
        console.print(f"stored as calibration #{cal_id}")


# ---------------------------------------------------------------- report


@app.command()
def report(
    meas: Path | None = typer.Argument(None, help="Measurement table (CSV) to plot over the model."),
    calibration: Path | None = typer.Option(
        None, "--calibration", "-c", help="Calibration JSON (default: fit the table by least squares)."
    ),
    out: Path = typer.Option(
        Path("stickslip-report"), "-o", "--output", metavar="FOLDER", help="Directory for the PNGs and index.html."
    ),
    db: str | None = db_option(" Used when MEAS.csv is not given."),
    device: str | None = typer.Option(None, "--device", "-d", help="From the database: only this device."),
    validate_on: Path | None = typer.Option(
        None,
        "--validate-on",
        help="A separate measurement table (CSV) to validate on, out-of-sample. Without it the report "
        "validates on MEAS.csv and says in-sample when that is the table the calibration was made from.",
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the list of files written as JSON."),
) -> None:
    """Write the paper's figures (Figs. 4, 6/10, 8, 9) and an HTML validation page.

    Figures: measured prismatic steps against zeta with a model line per tilt;
    rotary steps per traversed interval beside the model's average over it (one
    panel row per day in both); simulated steps along the range; d against the
    step difference, exact relation vs the paper's quadratic; the validation,
    labelled in-sample (MEAS.csv is the calibration's own table, by its sha256)
    or out-of-sample (--validate-on).

    Example: [bold]stickslip report -c cal.json meas.csv --validate-on other-day.csv -o report/[/]
    """
    from ..calibration import Calibration, CalibrationError, calibrate
    from ..report import build_report

    ts, _where = _traverses_from(meas, db, device, None, checked=True)
    if calibration is not None:
        with user_errors():
            cal = Calibration.load(calibration)
    else:
        with user_errors(CalibrationError):
            cal = calibrate(ts, method="lsq")
    from ..clock import age_days

    latest = max(t.day for t in ts)
    age = age_days(cal.day, latest)
    if age is not None and age > 0:
        warn_later(f"calibration is from {cal.day}, {age} day(s) before the latest data ({latest}): "
                   "the figures compare it with later days")
    val = read_table(validate_on) if validate_on is not None else None
    with user_errors(ImportError):
        rep = build_report(cal, ts, out, validation=val)
    if json_out:
        print_json(
            {
                "directory": str(out),
                "html": str(rep.html),
                "figures": [str(p) for p in rep.figures],
                "validation": {"sample": rep.sample.kind, "reason": rep.sample.reason},
            }
        )
        return
    for p in rep.figures:
        say(f"wrote {p}", keep=(p,))
    console.print(f"validation {rep.sample.kind}: {rep.sample.reason}", highlight=False)
    say(f"open {rep.html}", keep=(rep.html,))
