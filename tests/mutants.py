"""Seeded mutants: does the default test tier catch them? Run by hand, not by pytest.

    python tests/mutants.py                    # every mutant, against this checkout
    python tests/mutants.py --only adjoint     # one (names below)
    python tests/mutants.py --root OTHER_TREE  # the tests and library of another tree

For each mutant the tree (library, tests, docs) is copied to a temporary folder, one edit is
made to the copy's library source, and the default tier runs there (``python -m pytest -n 2
-x -p no:cacheprovider tests``, the copy first on ``PYTHONPATH``): it stops at the first
failing test. A mutant is caught when a test fails. The runs share one compilation cache
(``--cache``, default a new temporary folder), so a run compiles again only the programs the
mutant changed. The script exits with 1 if any mutant is not caught.

The mutants, each an error a change could plausibly introduce:

* ``jvp_sign``: a sign flipped in a hand-written derivative rule (``rotvec_to_quaternion``'s
  ``custom_jvp``: the ``v dk`` term of the x component).
* ``se3_cut``: a threshold moved by a factor of 10 (the SE(3) coefficients' series is used up
  to ``t^2 < 10`` instead of 1, with the terms chosen for 1).
* ``lock_range``: a wrong Euler output range at gimbal lock (the zeroed angle becomes 2 pi:
  the same rotation, outside ``[-pi, pi]`` and not scipy's 0).
* ``apply_norm``: a dropped normalisation (``quaternion_apply`` rotates by the prescaled
  quaternion, not by the unit one: right only for unit quaternions).
* ``adjoint``: a wrong adjoint block (``se3_adjoint``'s bottom-left ``R hat(t)`` instead of
  ``hat(t) R``).
* ``eigen_gap``: a factor of 2 in the eigen kernel's derivative rule (the gaps' reciprocals
  ``1 / g`` become ``1 / (2 g)``: the nearest rotation's, the mean's and Wahba's derivatives
  halved).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# name -> (file, original text, mutated text, count of occurrences replaced)
MUTANTS = {
    "jvp_sign": (
        "rotjax/_rotvec.py",
        "out = (k * dx + x * dk, ",
        "out = (k * dx - x * dk, ",
        1,
    ),
    "se3_cut": ("rotjax/_se3.py", "    small = x < _CUT\n", "    small = x < 10 * _CUT\n", 1),
    "lock_range": (
        "rotjax/_euler.py",
        "jnp.where(locked, 0.0, out[2])",
        "jnp.where(locked, 2 * jnp.pi, out[2])",
        1,
    ),
    "apply_norm": (
        "rotjax/_quaternion.py",
        "d = quat_turn([x * r for x in p], v)",
        "d = quat_turn(p, v)",
        1,
    ),
    "adjoint": (
        "rotjax/_se3.py",
        "_blocks(R, matmul(nm.skew(t), R), R)",
        "_blocks(R, matmul(R, nm.skew(t)), R)",
        1,
    ),
    "eigen_gap": (
        "rotjax/_eigen.py",
        "inv_g = [safe_div(1.0, g, tol) for g in gaps]",
        "inv_g = [safe_div(0.5, g, tol) for g in gaps]",
        1,
    ),
}
_IGNORE = shutil.ignore_patterns(".git", "__pycache__", ".pytest_cache", ".hypothesis", "site")


def _mutate(tree: Path, name: str) -> None:
    path, old, new, count = MUTANTS[name]
    src = (tree / path).read_text()
    if src.count(old) != count:
        raise SystemExit(f"{name}: {old!r} found {src.count(old)} times in {path}")
    src = src.replace(old, new)
    (tree / path).write_text(src)


def run(root: Path, name: str, cache: str, workers: int, extra: list[str]) -> tuple[bool, str]:
    """Whether the default tier catches mutant ``name``, and the failing tests it reports."""
    with tempfile.TemporaryDirectory(prefix=f"rotjax-mutant-{name}-") as tmp:
        tree = Path(tmp) / "tree"
        shutil.copytree(root, tree, ignore=_IGNORE)
        _mutate(tree, name)
        env = {k: v for k, v in os.environ.items() if k != "CI"}  # CI would take a fresh cache
        env["PYTHONPATH"] = os.pathsep.join([str(tree), env.get("PYTHONPATH", "")])
        env["ROTJAX_TEST_CACHE"] = cache
        found = subprocess.run(
            [sys.executable, "-c", "import rotjax; print(rotjax.__file__)"],
            cwd=tree, env=env, capture_output=True, text=True, check=True,
        ).stdout  # fmt: skip
        if not found.startswith(str(tree)):
            raise SystemExit(f"the copy's rotjax is not the one imported: {found}")
        cmd = [sys.executable, "-m", "pytest", "-n", str(workers), "-x", "-p", "no:cacheprovider"]
        done = subprocess.run(
            [*cmd, "-q", *extra, "tests"], cwd=tree, env=env, capture_output=True, text=True
        )
    failed = sorted(set(re.findall(r"^(?:FAILED|ERROR) (\S+)", done.stdout, re.M)))
    if done.returncode not in (0, 1) and not failed:
        tail = "\n".join(done.stdout.splitlines()[-20:])
        raise SystemExit(f"{name}: pytest exited {done.returncode}\n{tail}\n{done.stderr[-2000:]}")
    return done.returncode != 0, ", ".join(failed)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parent.parent)
    parser.add_argument("--only", nargs="*", choices=sorted(MUTANTS), default=list(MUTANTS))
    parser.add_argument("--cache", help="compilation cache folder (default: a new one)")
    parser.add_argument("-n", "--workers", type=int, default=2)
    parser.add_argument("extra", nargs="*", help="more pytest arguments (after --)")
    args = parser.parse_args()
    cache = args.cache or tempfile.mkdtemp(prefix="rotjax-mutants-cache-")
    missed = 0
    print(f"{'mutant':<12} {'caught':<7} {'seconds':>7}  failing tests", flush=True)
    for name in args.only:
        start = time.perf_counter()
        caught, tests = run(args.root.resolve(), name, cache, args.workers, args.extra)
        missed += not caught
        seconds = time.perf_counter() - start
        print(f"{name:<12} {'yes' if caught else 'NO':<7} {seconds:7.0f}  {tests}", flush=True)
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
