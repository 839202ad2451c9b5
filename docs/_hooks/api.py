"""MkDocs hook: the API reference (``docs/api/*.md``, one page per area) must document every
name in ``rotjax.__all__`` exactly once.

``__all__`` and the explicit re-exports (``from ._x import f as f``) are read from
``rotjax/__init__.py`` without importing the package. The build fails if they differ, if a
public name has no ``::: rotjax.<name>`` entry in the reference or more than one, or if an
entry names a function that is not public.
"""

from __future__ import annotations

import ast
import re
from collections import Counter
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


def on_files(files, config):
    entries = Counter()
    for f in files:
        if f.src_uri.startswith("api/") and f.src_uri.endswith(".md"):
            text = Path(f.abs_src_path).read_text()
            entries.update(re.findall(r"^::: rotjax\.(\w+)", text, flags=re.M))
    public = _public_names()
    listed = set(entries)
    twice = sorted(name for name, n in entries.items() if n > 1)
    if listed != public or twice:
        raise ValueError(
            "docs/api/ and rotjax.__all__ differ: missing "
            f"{sorted(public - listed)}, not public {sorted(listed - public)}, "
            f"listed more than once {twice}"
        )
    return files
