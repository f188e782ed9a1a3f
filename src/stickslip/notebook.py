"""Rich display in Jupyter: one HTML table helper for every result object's ``_repr_html_``.

Standard library only (it sits at the bottom of the package). Values are formatted by
the caller, with units in the column headers; everything is HTML-escaped here.
"""

from __future__ import annotations

import html
from collections.abc import Iterable, Sequence

__all__ = ["html_table"]


def html_table(title: str, headers: Sequence[str], rows: Iterable[Sequence[object]], notes: Sequence[str] = ()) -> str:
    """A small HTML table: a bold ``title``, a header row, the rows, then ``notes`` as lines below.

    >>> html_table("t", ["a (nm)"], [[1.5]])
    '<div><b>t</b><table><thead><tr><th>a (nm)</th></tr></thead><tbody><tr><td>1.5</td></tr></tbody></table></div>'
    """
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in r) + "</tr>" for r in rows)
    tail = "".join(f"<div>{html.escape(n)}</div>" for n in notes)
    return (
        f"<div><b>{html.escape(title)}</b><table><thead><tr>{head}</tr></thead>"
        f"<tbody>{body}</tbody></table>{tail}</div>"
    )
