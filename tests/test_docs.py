"""The documentation's Python examples run, and its format holds (`.ci/doc_examples.py`).

Slow tier (CI): each page, and each part of the docstrings, runs in a Python process of its
own, as a reader would run it (no test configuration: default dtype promotion, float32 unless
the page enables float64), sharing the run's compilation cache (conftest.py)."""

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / ".ci" / "doc_examples.py"
_spec = importlib.util.spec_from_file_location("doc_examples", SCRIPT)
docs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(docs)

PAGES = [str(p.relative_to(ROOT)) for p in docs.pages(ROOT) if docs.BLOCK.search(p.read_text())]
DOCSTRING_PARTS = 4  # the docstrings' examples take about a minute cold: split between workers

pytestmark = pytest.mark.slow


def _examples(*args) -> int:
    """Runs the script with `args` from the repository root; the number of examples it ran."""
    res = subprocess.run(
        [sys.executable, str(SCRIPT), *args], cwd=ROOT, capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr[-6000:]
    found = re.findall(rf"^{re.escape(docs.SUMMARY)} (\d+), failed 0$", res.stderr, re.M)
    assert found, res.stderr[-2000:]
    return int(found[-1])


def test_format_of_pages_and_docstrings(monkeypatch):
    monkeypatch.chdir(ROOT)
    assert docs.format_errors() == []


@pytest.mark.parametrize("page", PAGES)
def test_page_examples_run(page):
    assert _examples(page) > 0


@pytest.mark.parametrize("part", range(DOCSTRING_PARTS))
def test_docstring_examples_run(part):
    assert _examples(docs.DOCSTRINGS, f"{part}/{DOCSTRING_PARTS}") > 0
