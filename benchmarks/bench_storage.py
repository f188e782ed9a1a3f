"""Storage benchmark: the PostgreSQL backend against SQLite, side by side, on the same 1e5 traverses.

Each operation runs on both backends in the same run, on the same rows, each on a fresh
database, best of ``--repeat`` runs (default 3); the table gives the seconds and the ratio
PostgreSQL / SQLite (the target: within 2x for import and history):

* import: ``Store.add_traverses`` of every row in one transaction (content keys, sessions,
  SQLite's executemany, PostgreSQL's COPY), then the same through ``stickslip import`` in
  this process (the table read and checked, duplicates looked up, the rows stored);
* history: ``Store.history()`` (one GROUP BY over every row) and ``stickslip history --json``;
* read: ``Store.traverses()`` (every row back as Traverse objects) and ``iter_traverses``
  (10 000 at a time: SQLite's cursor, PostgreSQL's cursor WITH HOLD).

SQLite is the file (WAL, ``synchronous=FULL``) in a temporary folder; PostgreSQL is a
throwaway server (``tests/support/pgserver.py``) started with its defaults (fsync on), on
this machine, reached over TCP on 127.0.0.1 with a password, as a rig reaches the lab's.
A server on another machine adds the network's round trips (one per transaction and
statement, not per row).

Run: ``.venv/bin/python benchmarks/bench_storage.py`` (1e5 rows; ``--rows N``,
``--repeat K``, ``--quick``: 2000 rows, one run), or ``make bench``.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "support"))


def traverses(n: int) -> list:  # list[Traverse]
    """``n`` traverses: the paper's poses, both joints and directions, 3 repeats a day over many days."""
    import datetime

    import numpy as np
    from synth import paper_table

    from stickslip.measurements import Traverse

    rng = np.random.default_rng(0)
    base = paper_table()
    out = []
    for i in range(n):
        t = base[i % len(base)]
        day = (datetime.date(2026, 1, 1) + datetime.timedelta(days=i // (3 * len(base)))).isoformat()
        steps = max(1, round(t.steps * (1 + 0.003 * rng.standard_normal())))
        out.append(Traverse(day, t.joint, t.direction, t.q1, t.q2, t.q3, t.theta, t.psi, t.start, t.end, steps))
    return out


def best(fn: Callable[[], object], setup: Callable[[], None], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        setup()
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv: Sequence[str] | None = None) -> list[dict[str, object]]:
    args = list(argv or [])
    quick = "--quick" in args
    n = 2000 if quick else 100_000
    repeat = 1 if quick else 3
    for flag in ("--rows", "--repeat"):
        if flag in args:
            value = int(float(args[args.index(flag) + 1]))
            n, repeat = (value, repeat) if flag == "--rows" else (n, value)

    import pgserver
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import write_measurements
    from stickslip.storage import Store

    try:
        server = pgserver.start(durable=True)
    except pgserver.Unavailable as e:
        print(f"no PostgreSQL server here ({e}): nothing to compare")
        return []
    os.environ["PGPASSWORD"] = server.password
    rows = traverses(n)
    tmp = Path(tempfile.mkdtemp(prefix="stickslip-bench-"))
    table = tmp / "m.csv"
    write_measurements(table, rows)
    runner = CliRunner()
    fresh = {"n": 0}

    def new_target(kind: str) -> str:
        fresh["n"] += 1
        if kind == "sqlite":
            return str(tmp / f"b{fresh['n']}.db")
        return server.url(server.new_schema())

    results: list[dict[str, object]] = []
    print(f"{n} traverses; best of {repeat}; PostgreSQL {server.admin('SHOW server_version')[0][0]} on 127.0.0.1")
    print(f"{'operation':<34}{'SQLite s':>10}{'PostgreSQL s':>14}{'PG/SQLite':>11}")
    try:
        filled: dict[str, str] = {}
        for kind in ("sqlite", "postgresql"):
            filled[kind] = new_target(kind)
            with Store.open(filled[kind]) as st:
                st.add_traverses(rows, device="sim://")

        def one(label: str, op: Callable[[str], object], needs_fresh: bool) -> None:
            secs: dict[str, float] = {}
            for kind in ("sqlite", "postgresql"):
                target = {"t": filled[kind]}

                def setup(kind: str = kind, target: dict[str, str] = target) -> None:
                    if needs_fresh:
                        target["t"] = new_target(kind)
                        with Store.open(target["t"]):
                            pass  # the schema made: an import is timed, not the migrations

                secs[kind] = best(lambda target=target: op(target["t"]), setup, repeat)
            ratio = secs["postgresql"] / secs["sqlite"]
            print(f"{label:<34}{secs['sqlite']:>10.3f}{secs['postgresql']:>14.3f}{ratio:>10.2f}x")
            results.append({"operation": label, "rows": n, **secs, "ratio": ratio})

        def store_import(t: str) -> None:
            with Store.open(t) as st:
                st.add_traverses(rows, device="sim://")

        def cli(args: list[str]) -> Callable[[str], None]:
            def run(t: str) -> None:
                r = runner.invoke(app, [*args, "--db", t])
                if r.exit_code != 0:
                    raise RuntimeError(r.output[-500:])

            return run

        def store_history(t: str) -> None:
            with Store.open(t) as st:
                st.history()

        def store_read(t: str) -> None:
            with Store.open(t) as st:
                assert len(st.traverses()) == n

        def store_iter(t: str) -> None:
            with Store.open(t) as st:
                assert sum(1 for _ in st.iter_traverses(chunk=10_000)) == n

        one("import: Store.add_traverses", store_import, True)
        one("import: stickslip import", cli(["import", str(table), "--device", "sim://", "--json"]), True)
        one("history: Store.history", store_history, False)
        one("history: stickslip history --json", cli(["history", "--json"]), False)
        one("read: Store.traverses", store_read, False)
        one("read: Store.iter_traverses", store_iter, False)
    finally:
        server.stop()
        import shutil

        shutil.rmtree(tmp, ignore_errors=True)
    worst = max((r["ratio"] for r in results if str(r["operation"]).split(":")[0] in ("import", "history")),
                default=math.nan)
    print(f"\nimport and history: PostgreSQL within {worst:.2f}x of SQLite (target: 2x)")
    return results


if __name__ == "__main__":
    main(sys.argv[1:])
