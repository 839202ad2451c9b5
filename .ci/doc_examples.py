"""Run the Python examples of the README and the docs pages, so that they cannot go stale.

Each file runs in its own process (one page's ``jax.config`` does not leak into the next); its
```python blocks run in order, in one namespace (a page's examples may build on the ones before).
Usage, from the repository root: ``python .ci/doc_examples.py [FILE ...]``.
"""

import re
import subprocess
import sys
import traceback
from pathlib import Path

BLOCK = re.compile(r"^```python\n(.*?)^```", flags=re.S | re.M)


def run_file(path: Path) -> int:
    namespace = {"__name__": "__main__"}
    failed = 0
    for i, code in enumerate(BLOCK.findall(path.read_text())):
        try:
            exec(compile(code, f"{path}, example {i + 1}", "exec"), namespace)
        except Exception:
            failed += 1
            print(f"FAILED: {path}, example {i + 1}", file=sys.stderr)
            traceback.print_exc()
    return failed


def main(argv: list[str]) -> int:
    if len(argv) == 1:
        return 1 if run_file(Path(argv[0])) else 0
    files = [Path(p) for p in argv] or [Path("README.md"), *sorted(Path("docs").rglob("*.md"))]
    codes = [
        subprocess.run([sys.executable, __file__, str(p)], stdout=subprocess.DEVNULL).returncode
        for p in files
        if BLOCK.search(p.read_text())
    ]
    return 1 if any(codes) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
