"""MkDocs hook: the API page must document every name in ``rotjax.__all__``.

``__all__`` and the explicit re-exports (``from ._x import f as f``) are read from
``rotjax/__init__.py`` without importing the package. The build fails if they differ, or if a
public name has no ``::: rotjax.<name>`` entry on the API page (or an entry names a function
that is not public).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

INIT = Path(__file__).resolve().parents[2] / "rotjax" / "__init__.py"


def _public_names() -> set[str]:
    body = ast.parse(INIT.read_text()).body
    exported = {
        a.asname for node in body if isinstance(node, ast.ImportFrom) for a in node.names
    } - {None}
    for node in body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            names = set(ast.literal_eval(node.value))
            if names != exported:
                raise ValueError(
                    f"rotjax.__all__ and the re-exports differ: re-exported only "
                    f"{sorted(exported - names)}, in __all__ only {sorted(names - exported)}"
                )
            return names
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
