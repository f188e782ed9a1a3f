"""The hand-parsed benchmarks' flags checked before anything runs.

Several benchmarks read their few flags from ``sys.argv`` by hand; without a check a mistyped flag (or
``--help``) fell through to the default run, which for the vision benchmarks is the held-out renderer: a
measurement the house keeps for the end. :func:`check_flags` prints the module's docstring for ``-h`` /
``--help`` and refuses an unknown flag with the known ones (exit 2), as argparse would.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence


def check_flags(args: Sequence[str], flags: Iterable[str], doc: str | None) -> None:
    """Exit 0 after printing ``doc`` on ``-h``/``--help``; exit 2 on a flag not in ``flags``."""
    known = set(flags)
    if "-h" in args or "--help" in args:
        print(doc or "")
        sys.exit(0)
    unknown = [a for a in args if a.startswith("--") and a not in known]
    if unknown:
        print(f"{sys.argv[0]}: unknown option {unknown[0]!r}; one of {sorted(known)} (see --help)", file=sys.stderr)
        sys.exit(2)
