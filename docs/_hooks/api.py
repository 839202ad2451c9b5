"""MkDocs hook: the API page must document every name in ``rotjax.__all__``.

``__all__`` is read from ``rotjax/__init__.py`` without importing the package; a public name
with no ``::: rotjax.<name>`` entry on the API page (or an entry for a name not in ``__all__``)
fails the build.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

INIT = Path(__file__).resolve().parents[2] / "rotjax" / "__init__.py"


def _public_names() -> set[str]:
    for node in ast.parse(INIT.read_text()).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return set(ast.literal_eval(node.value))
    raise ValueError(f"{INIT} defines no __all__")


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri != "api.md":
        return markdown
    listed = set(re.findall(r"^::: rotjax\.(\w+)", markdown, flags=re.M))
    public = _public_names()
    if listed != public:
        raise ValueError(
            "docs/api.md and rotjax.__all__ differ: missing "
            f"{sorted(public - listed)}, not public {sorted(listed - public)}"
        )
    return markdown
