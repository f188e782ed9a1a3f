"""Round trips of the history: what goes out of a store (export, backup) and comes back in is the same, and is known.

A table exported from one store and imported into another (docs/storage.md: a rig's file moved into the lab's
PostgreSQL), or into the same one again, keeps every value and its rows are recognised as already stored.
"""

from __future__ import annotations

import math

from stickslip.measurements import Traverse, measurements_to_csv, parse_measurements
from stickslip.storage import Store
from stickslip.storage.schema import _content_keys


def _rows() -> list[Traverse]:
    # np.round(-1e-9, 6) and -1 * 0.0 are -0.0: a table written by numpy or pandas holds negative zeros
    return [
        Traverse("2026-11-20", 3, "+", -0.0, -1.0, 0.0, -0.0, 0.0, -0.0, 0.01, 10),
        Traverse("2026-11-20", 1, "-", 0.0, -0.5, 0.004, 0.0, -0.0, 0.3, -0.0, 1234),
    ]


def test_an_exported_table_with_negative_zeros_is_known_as_stored(db):
    """SQLite stores -0.0 as 0: the export writes 0.0, and its rows must have the keys they were stored with."""
    rows = _rows()
    with Store.open(db) as st:
        st.add_traverses(rows, device="sim://", how="imported")
        exported = parse_measurements(measurements_to_csv(st.iter_traverses()))
        assert exported == rows  # equal as numbers (-0.0 == 0.0)
        assert st.duplicates(exported, "sim://") == [0, 1]
        assert st.duplicates(rows, "sim://") == [0, 1]
        assert st.device_holding(exported) is not None


def test_a_row_stored_with_the_signed_zero_key_of_before_is_still_found(db):
    rows = _rows()
    with Store.open(db) as st:
        (tid, _) = st.add_traverses(rows, device="sim://")
        signed = _content_keys(rows[:1], "sim://", signed_zeros=True)[0]
        with st._write() as con:  # the key a row with -0.0 was stored with before zeros were unsigned
            con.execute("UPDATE traverses SET content = ? WHERE id = ?", (signed, tid))
        assert st.duplicates(rows, "sim://") == [0, 1]
        assert signed != _content_keys(rows[:1], "sim://")[0]
        assert math.copysign(1.0, rows[0].q1) < 0
