"""Run the Python examples of the README, the docs pages and the public docstrings, and check
the docstrings' format, so that neither can go stale.

Pages: each file runs in its own process (one page's `jax.config` does not leak into the
next); its ```python blocks run in order, in one namespace (a page's examples may build on the
ones before). Docstrings: one process; each public object's blocks run in a namespace of
their own, so every example states its imports.

The docstring format (checked here for every name in `rotjax.__all__` and every documented
method of the public classes; Google style, rendered by mkdocstrings):

* Signature: every parameter and the return value annotated; arrays in as
  `jax.typing.ArrayLike` (`from jax.typing import ArrayLike`), arrays out as `jax.Array`
  (`from jax import Array`), several outputs as `tuple[Array, Array]`. Shapes go in the prose.
* `Args:`: `name: (..., 4) quaternion, ...` with the shape in backticks first; continuation
  lines indented by four more spaces.
* `Returns:`: one item per returned value, the description starting with the shape in
  backticks: `` `(..., 3, 3)` active rotation matrix... ``; for a tuple, one named item per
  element (`axis: ...`, `angle: ...`). Continuation lines indented by four more spaces (a line
  at the item's indentation starts a new item). The rendered type comes from the signature:
  a first line `name (type): ...` must give a type, never a shape or prose.
* `Examples:`: a fenced ```python block that runs as it stands (imports included).
* Cross-references in Markdown, `` [`quaternion_to_matrix`][rotjax.quaternion_to_matrix] ``,
  code in single backticks: no reST roles (`:func:`, `:class:`, ...) and no double backticks.

The check fails on a reST role in a public docstring or a docs page, on install commands of the
docs' home page that differ from the README's two, a double-backtick span
in a public docstring, a Returns type that is not a type expression, a missing Returns or
Examples section or annotation, or a warning from the docstring parser.
Usage, from the repository root: `python .ci/doc_examples.py [FILE ...]` (no FILE: the
README, every page under docs/, then the docstring check and examples);
`--docstrings [K/N]` runs the docstrings' examples (the K-th of N parts). The test suite's slow
tier (`tests/test_docs.py`) runs them in these parts, and `format_errors` in its own process.
"""

import ast
import functools
import os
import re
import subprocess
import sys
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

BLOCK = re.compile(r"^```python\n(.*?)^```", flags=re.S | re.M)
ROLE = re.compile(r":(?:py:)?(?:func|class|meth|data|attr|mod|obj|exc|ref|const|term):`")
DOUBLE_BACKTICK = re.compile(r"(?<!`)``(?!`)")
DOCSTRINGS = "--docstrings"
SUMMARY = "examples run:"  # the last line of a run's stderr: how many examples ran
# Documented dunder methods that are part of the API (operators and calls).
API_DUNDERS = {"__call__", "__mul__", "__pow__"}


def _run_blocks(blocks, fresh_namespace: bool) -> int:
    """Execute `(name, code)` blocks in order, in one namespace or (`fresh_namespace`) each in
    its own; report each failure and, last on stderr, how many ran and failed."""
    namespace = {"__name__": "__main__"}
    failed = ran = 0
    for name, code in blocks:
        ran += 1
        if fresh_namespace:
            namespace = {"__name__": "__main__"}
        try:
            exec(compile(code, name, "exec"), namespace)
        except Exception:
            failed += 1
            print(f"FAILED: {name}", file=sys.stderr)
            traceback.print_exc()
    print(f"{SUMMARY} {ran}, failed {failed}", file=sys.stderr)
    return failed


def run_file(path: Path) -> int:
    blocks = BLOCK.findall(path.read_text())
    return _run_blocks(((f"{path}, example {i + 1}", code) for i, code in enumerate(blocks)), False)


@functools.cache
def _options() -> dict:
    """The mkdocstrings docstring options of mkdocs.yml, so the check parses as the site does."""
    import yaml

    class Loader(yaml.SafeLoader):  # mkdocs.yml may hold !!python tags: ignore them
        pass

    Loader.add_multi_constructor("", lambda loader, suffix, node: None)
    config = yaml.load(Path("mkdocs.yml").read_text(), Loader=Loader)
    for plugin in config["plugins"]:
        if isinstance(plugin, dict) and "mkdocstrings" in plugin:
            options = plugin["mkdocstrings"]["handlers"]["python"]["options"]
            return dict(options.get("docstring_options", {}))
    return {}


def public_objects():
    """`(path, griffe object, kind)` for every public function, class, method and property."""
    import griffe

    package = griffe.load("rotjax", search_paths=["."], docstring_parser="google")
    for name in _all_names():
        obj = package[name]
        obj = obj if obj.is_module else obj.final_target
        if obj.is_module:  # a public submodule (rotjax.manifold): its own public functions
            for member_name, member in obj.members.items():
                if not member_name.startswith("_") and not member.is_alias and member.is_function:
                    yield f"rotjax.{name}.{member_name}", member, "function"
        elif obj.is_class:
            yield f"rotjax.{name}", obj, "class"
            for member_name, member in obj.members.items():
                if member.is_alias or not member.docstring:
                    continue
                if member_name.startswith("_") and member_name not in API_DUNDERS:
                    continue
                kind = "property" if "property" in member.labels else "method"
                yield f"rotjax.{name}.{member_name}", member, kind
        else:
            yield f"rotjax.{name}", obj, "function"


def _all_names() -> list[str]:
    tree = ast.parse(Path("rotjax/__init__.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return list(ast.literal_eval(node.value))
    raise ValueError("rotjax/__init__.py defines no __all__")


_TYPE_NODES = (ast.Name, ast.Attribute, ast.Subscript, ast.Load, ast.BitOr)


def is_type(annotation) -> bool:
    """Whether a rendered annotation is a type expression: names, attributes, subscripts,
    `X | Y` and `None`; a shape such as `(..., 3)` or prose is not."""
    if annotation is None or isinstance(annotation, str):
        return False  # missing, or text the parser could not read as an expression
    try:
        tree = ast.parse(str(annotation), mode="eval").body
    except SyntaxError:
        return False

    def ok(node, in_subscript=False):
        if isinstance(node, ast.Constant):
            return node.value is None or (in_subscript and isinstance(node.value, str))
        if isinstance(node, ast.Tuple):
            return in_subscript and all(ok(e, True) for e in node.elts)
        if isinstance(node, ast.BinOp):
            return isinstance(node.op, ast.BitOr) and ok(node.left) and ok(node.right)
        if isinstance(node, ast.Subscript):
            return ok(node.value) and ok(node.slice, True)
        if isinstance(node, ast.Attribute):
            return ok(node.value)
        return isinstance(node, ast.Name)

    return ok(tree)


def examples(obj) -> list[str]:
    """The ```python blocks of an object's `Examples:` section."""
    from griffe import DocstringSectionKind, Parser

    sections = obj.docstring.parse(Parser.google, **_options()) if obj.docstring else []
    return [
        code
        for section in sections
        if section.kind is DocstringSectionKind.examples
        for _, text in section.value
        for code in BLOCK.findall(text + "\n")
    ]


def check_docstrings() -> list[str]:
    """The format errors of the public docstrings (see the module docstring)."""
    import logging

    from griffe import DocstringSectionKind, Parser

    options = _options()
    messages: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record):
            messages.append(record.getMessage())

    handler = Collect(level=logging.WARNING)
    logging.getLogger("griffe").addHandler(handler)
    errors = []
    for path, obj, kind in public_objects():
        text = obj.docstring.value if obj.docstring else ""
        if not text:
            errors.append(f"{path}: no docstring")
            continue
        if ROLE.search(text):
            errors.append(f"{path}: reST role {ROLE.search(text).group(0)!r}")
        if DOUBLE_BACKTICK.search(text):
            errors.append(f"{path}: double backticks (use single ones)")
        del messages[:]
        sections = obj.docstring.parse(Parser.google, **options)
        errors += [f"{path}: docstring parser: {m}" for m in messages]
        kinds = {s.kind: s for s in sections}
        if kind in ("function", "method"):
            params = [p for p in obj.parameters if p.name not in ("self", "cls")]
            errors += [
                f"{path}: parameter {p.name!r} not annotated"
                for p in params
                if p.annotation is None
            ]
            returns = kinds.get(DocstringSectionKind.returns)
            if returns is None:
                errors.append(f"{path}: no Returns section")
            else:
                ret = obj.returns  # a union (`A | tuple[A, B]`): items give their own types
                n = len(ret.slice.elements) if getattr(ret, "is_tuple", False) else 1
                if len(returns.value) != n and "|" not in str(ret):
                    errors.append(
                        f"{path}: Returns has {len(returns.value)} items for {n} value(s) "
                        "(indent continuation lines)"
                    )
                for item in returns.value:
                    if item.annotation is None:
                        errors.append(f"{path}: no return type (annotate the signature)")
                    elif not is_type(item.annotation):
                        errors.append(
                            f"{path}: Returns type {str(item.annotation)!r} is not a type"
                        )
        if kind != "property":
            if not examples(obj):
                errors.append(f"{path}: no Examples section with a ```python block")
    logging.getLogger("griffe").removeHandler(handler)
    return errors


def install_commands(path: Path) -> list[str]:
    """The `pip install ...` command lines of a page."""
    return [ln.strip() for ln in path.read_text().splitlines() if ln.startswith("pip install -e")]


def check_pages(files: list[Path]) -> list[str]:
    errors = []
    for p in files:
        for i, line in enumerate(p.read_text().splitlines(), 1):
            if ROLE.search(line):
                errors.append(f"{p}:{i}: reST role {ROLE.search(line).group(0)!r}")
    return errors


def check_install_commands() -> list[str]:
    """The docs' home page repeats the README's two commands: they must not drift apart."""
    readme, home = install_commands(Path("README.md"))[:2], install_commands(Path("docs/index.md"))
    if home[:2] != readme:
        return [f"docs/index.md: install commands {home[:2]} differ from README's {readme}"]
    return []


def run_docstrings(part: int = 0, parts: int = 1) -> int:
    return _run_blocks(
        (
            (f"{path}, example {i + 1}", code)
            for path, obj, _ in list(public_objects())[part::parts]
            for i, code in enumerate(examples(obj))
        ),
        True,
    )


def format_errors() -> list[str]:
    """The format errors of the README, docs/ and the public docstrings."""
    return check_pages(pages()) + check_install_commands() + check_docstrings()


def pages(root: Path = Path()) -> list[Path]:
    """The README and every page under docs/, as paths under `root`."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def main(argv: list[str]) -> int:
    if argv[:1] == [DOCSTRINGS]:
        part, parts = map(int, (argv[1] if len(argv) > 1 else "0/1").split("/"))
        return 1 if run_docstrings(part, parts) else 0
    if len(argv) == 1:
        return 1 if run_file(Path(argv[0])) else 0
    files = [Path(p) for p in argv] or pages()
    errors = [] if argv else format_errors()
    for e in errors:
        print(f"DOCS CHECK: {e}", file=sys.stderr)
    runs = [[str(p)] for p in files if BLOCK.search(p.read_text())]
    if not argv:
        runs.insert(0, [DOCSTRINGS])  # the longest run first
    # one process per page (and one for the docstrings), as many at a time as there are cores
    with ThreadPoolExecutor(os.cpu_count() or 1) as pool:
        codes = list(pool.map(_run_process, runs))
    return 1 if errors or any(codes) else 0


def _run_process(run: list[str]) -> int:
    return subprocess.run([sys.executable, __file__, *run], stdout=subprocess.DEVNULL).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
