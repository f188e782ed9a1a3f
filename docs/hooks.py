"""mkdocs hook: a page holding ``<!-- notebook: NAME.ipynb -->`` shows that notebook's cells.

Markdown cells are copied; code cells become Python code blocks. The notebooks are kept
without outputs (the test suite runs them on the simulator), so the page shows the code and
the prose, with a link to download the notebook. No extra dependency: a notebook is JSON.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

_MARK = re.compile(r"<!-- notebook: ([\w.-]+\.ipynb) -->")


def _render(path: Path) -> str:
    nb = json.loads(path.read_text(encoding="utf-8"))
    parts = []
    for cell in nb["cells"]:
        text = "".join(cell["source"]).rstrip()
        if not text:
            continue
        if cell["cell_type"] == "markdown":
            parts.append(text)
        elif cell["cell_type"] == "code":
            parts.append(f"```python\n{text}\n```")
    link = f"[Download the notebook ({path.name})]({path.name})"
    return "\n\n".join([*parts[:1], link, *parts[1:]]) + "\n"


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """Replace each notebook mark with the notebook's cells."""
    folder = Path(page.file.abs_src_path).parent
    return _MARK.sub(lambda m: _render(folder / m.group(1)), markdown)
