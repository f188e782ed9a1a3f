"""The measurement table: one traverse per row (docs/design.md §7).

CSV header, exactly::

    day,joint,direction,q1,q2,q3,theta,psi,start,end,steps

``day`` is a session label (ISO date preferred); ``q1, q2, q3`` hold the fixed joints
(the moving joint's column is ignored); ``start, end`` is the traversed interval of
the moving joint; ``steps`` a positive integer. All values SI (rad, m).

Rows that break these rules are never skipped: :func:`read_measurements` collects
every problem as ``file:line: reason`` and raises :class:`TableError`.

The package, by concept: :mod:`.rows` (a row: :class:`Traverse` and its checks),
:mod:`.chunks` (reading CSV a chunk at a time, as columns), :mod:`.table` (the
measurement table: :class:`TraverseTable`, read, parse, write) and :mod:`.poses` (the
pose tables ``stickslip predict`` reads) and :mod:`.steps` (step sizes measured at a pose, by a
camera: :class:`StepSize`). Everything is imported from here.
"""

from .chunks import CHUNK_ROWS
from .poses import (
    POSE_TABLE_REQUIRED,
    PoseChunk,
    PoseQuery,
    PoseTable,
    parse_pose_columns,
    parse_pose_table,
    read_pose_columns,
    read_pose_table,
    stream_pose_table,
)
from .rows import (
    HEADER,
    MAX_STEPS,
    POSE_COLUMNS,
    TableError,
    Traverse,
    check_pose,
    check_traverses,
    parse_row,
    traverse_problems,
)
from .steps import STEP_HEADER, StepSize, parse_step_sizes, read_step_sizes, step_sizes_to_csv, write_step_sizes
from .table import (
    TraverseTable,
    as_arrays,
    measurements_to_csv,
    parse_measurement_table,
    parse_measurements,
    read_measurement_table,
    read_measurements,
    stream_measurement_table,
    write_measurements,
)

__all__ = [
    "HEADER",
    "POSE_COLUMNS",
    "Traverse",
    "TraverseTable",
    "PoseTable",
    "TableError",
    "read_measurements",
    "parse_measurements",
    "read_measurement_table",
    "parse_measurement_table",
    "read_pose_columns",
    "parse_pose_columns",
    "write_measurements",
    "measurements_to_csv",
    "check_pose",
    "MAX_STEPS",
    "parse_row",
    "traverse_problems",
    "check_traverses",
    "CHUNK_ROWS",
    "as_arrays",
    "POSE_TABLE_REQUIRED",
    "PoseQuery",
    "parse_pose_table",
    "read_pose_table",
    "stream_measurement_table",
    "PoseChunk",
    "stream_pose_table",
    "STEP_HEADER",
    "StepSize",
    "parse_step_sizes",
    "read_step_sizes",
    "step_sizes_to_csv",
    "write_step_sizes",
]
