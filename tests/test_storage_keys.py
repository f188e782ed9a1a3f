"""Content keys computed in bulk (imports) equal the per-row definition (the key stored since schema 3)."""

from __future__ import annotations

import hashlib

from hypothesis import given, settings
from hypothesis import strategies as st

from stickslip.measurements import Traverse
from stickslip.storage import content_key
from stickslip.storage.schema import _content_keys, stored_device


def _key_as_defined(t: Traverse, device: str) -> str:
    """The definition: the device's stored name, floats to 12 digits, a negative zero as 0 (SQLite keeps no sign
    on a zero)."""
    values = [stored_device(device), str(t.day).strip(), str(int(t.joint)), t.direction]
    values += [f"{float(getattr(t, c)) + 0.0:.12g}" for c in ("q1", "q2", "q3", "theta", "psi", "start", "end")]
    values.append(str(int(t.steps)))
    return "sha256:" + hashlib.sha256("\x1f".join(values).encode()).hexdigest()


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=100, deadline=None)
@given(
    rows=st.lists(
        st.builds(
            Traverse, st.text(min_size=1, max_size=8), st.sampled_from([1, 2, 3]), st.sampled_from(["+", "-"]),
            finite, finite, finite, finite, finite, finite, finite, st.integers(1, 10**12),
        ),
        max_size=8,
    ),
    device=st.sampled_from(["sim://", " sim:// ", "nanocontrol:///dev/ttyUSB0?password=secret", "anc300://h:7230"]),
)
def test_bulk_keys_equal_the_definition(rows, device):
    want = [_key_as_defined(t, device) for t in rows]
    assert _content_keys(rows, device) == want
    assert [content_key(t, device) for t in rows] == want


def test_bulk_insert_returns_the_ids_of_the_rows_in_order(db):
    """add_traverses inserts in bulk (SQLite: one executemany; PostgreSQL: COPY): the ids are the new rows, in order."""
    from synth import paper_table

    from stickslip.storage import Store

    ts = paper_table()
    with Store.open(db) as st:
        first = st.add_traverses(ts[:5], device="sim://")
        st.delete_traverses([first[-1]])  # the largest id is free again
        ids = st.add_traverses(ts, device="sim://?seed=7")
        recs = {r["id"]: r for r in st.traverse_records(device="sim://?seed=7")}
    assert ids == sorted(ids) and len(set(ids)) == len(ts) and min(ids) > max(first[:-1])
    for i, t in zip(ids, ts, strict=True):
        r = recs[i]
        got = (r["day"], r["joint"], r["direction"], r["q2"], r["steps"])
        assert got == (t.day, t.joint, t.direction, t.q2, t.steps)
    with Store.open(db) as st:  # and the keys stored in bulk are the definition's
        assert st.duplicates(ts, "sim://?seed=7") == list(range(len(ts)))
