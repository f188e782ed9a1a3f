"""docs/taskspace.md: its Python example runs as written (docs/style.md: examples run) and its claims hold."""

from __future__ import annotations

import re
from pathlib import Path

DOC = (Path(__file__).resolve().parents[1] / "docs" / "taskspace.md").read_text(encoding="utf-8")


def test_python_example_runs_and_lands_near_the_target(tmp_path, monkeypatch, capsys):
    code = re.search(r"```python\n(.*?)```", DOC, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    ns: dict[str, object] = {}
    exec(compile(code, "docs/taskspace.md", "exec"), ns)
    assert (tmp_path / "reach.png").stat().st_size > 10_000
    out = capsys.readouterr().out
    share = float(re.search(r"\(([\d.]+)% of the move\)", out).group(1))
    assert share < 5.0, out  # the simulator's true end, within 5 % of the 49 µm move
    plan = ns["plan"]
    assert plan.end_error < 1e-6  # type: ignore[attr-defined]


def test_documented_json_keys_are_the_plans():
    from stickslip import kinematics as kin
    from stickslip.motion.reach import plan_reach
    from test_reach import CAL

    d = plan_reach(CAL, kin.Pose(0.0, -1.0, 0.003), by=(10e-6, 0.0, 0.0)).as_dict()
    assert set(d) == {"start", "target", "segments", "end"}
    assert set(d["start"]) == set(d["end"]) == {"q", "tip"} and set(d["segments"][0]) == {"steps", "q", "tip"}
    for key in ('"start"', '"target"', '"segments"', '"steps"', '"end"'):
        assert key in DOC
