"""Strict test environment: float64 enabled, strict dtype promotion, no implicit rank promotion
(JAX's own test setting: a constant of shape ``(4,)`` must not broadcast silently against a
``(..., 4)`` batch), a deadline-free profile.

Compiled programs are shared through JAX's persistent compilation cache, which the xdist
workers (and the notebooks' kernels) share: a program compiled by one test or worker is loaded,
not compiled again, by the others. Locally the cache is kept between runs, so a rerun compiles
only what changed: ``$ROTJAX_TEST_CACHE`` or ``~/.cache/rotjax/tests-jax-cache`` (under
``$XDG_CACHE_HOME`` if set); delete the folder for a cold run. JAX's cache key covers the
program, the compile options, the backend and the JAX and jaxlib versions, so an entry compiled
from other code is never loaded. In CI (``CI`` set to true) each run gets a fresh folder,
removed at its end. Tracing and lowering still run every time (errors raised while tracing are
raised as before).

The exhaustive sweeps are marked ``slow`` and left out of the default run (``-m "not slow"``
in pyproject.toml's addopts): the Euler sequences outside ``helpers.FAST_SEQS`` (marked here),
the cases that ``helpers.sweep`` leaves out, and a few whole second-derivative checks (marked
where they are defined). ``-m slow`` runs them, ``-m ""`` everything. With ``-n``, xdist's
``worksteal`` scheduling keeps both workers busy to the end of the run."""

import os
import shutil
import tempfile

import jax
import numpy as np
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")

_CACHE_ENV = "ROTJAX_TEST_CACHE"
_FRESH_ENV = "ROTJAX_TEST_FRESH_CACHE"  # the folder of a CI run, passed to its xdist workers


def _compilation_cache_dir() -> tuple[str, bool]:
    """The cache folder, and whether this process made it and removes it at its end: in CI a
    new temporary folder per run (an xdist worker takes its controller's, passed in the
    environment), else a kept folder."""
    if os.environ.get("CI", "").lower() in ("true", "1"):
        inherited = os.environ.get(_FRESH_ENV)
        if os.environ.get("PYTEST_XDIST_WORKER") and inherited and os.path.isdir(inherited):
            return inherited, False
        path = tempfile.mkdtemp(prefix="rotjax-jax-cache-")
        os.environ[_FRESH_ENV] = path  # inherited by the xdist workers started after this
        return path, True
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.environ.get(_CACHE_ENV) or os.path.join(base, "rotjax", "tests-jax-cache")
    os.makedirs(path, exist_ok=True)
    return path, False


_CACHE_DIR, _OWN_CACHE = _compilation_cache_dir()
_CACHE_CONFIG = {
    "jax_compilation_cache_dir": _CACHE_DIR,
    "jax_persistent_cache_min_compile_time_secs": 0,  # every program
    "jax_persistent_cache_min_entry_size_bytes": -1,  # of any size
}
for _name, _value in _CACHE_CONFIG.items():
    jax.config.update(_name, _value)
    os.environ[_name.upper()] = str(_value)  # for the notebooks' kernels and other subprocesses


def pytest_unconfigure(config):
    if _OWN_CACHE:
        shutil.rmtree(_CACHE_DIR, ignore_errors=True)


settings.register_profile(
    "rotjax",
    deadline=None,  # the first call of every example compiles
    max_examples=60,
    suppress_health_check=[HealthCheck.too_slow],
)
# A longer search for local runs: pytest --hypothesis-profile=deep
settings.register_profile("deep", parent=settings.get_profile("rotjax"), max_examples=600)
settings.load_profile("rotjax")
np.seterr(all="raise", under="ignore")  # underflow to 0 is fine in references


def pytest_collection_modifyitems(config, items):
    """Mark slow the cases of an exhaustive sweep over Euler sequences that the default run can
    leave out: in a test parametrized over all 24 sequences (under any argument name), every
    case whose sequence is not in ``helpers.FAST_SEQS``. Applies to every test file."""
    from helpers import FAST_SEQS, SEQS

    groups: dict = {}
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", None)
        if params:
            key = (item.path, getattr(item, "originalname", item.name))
            for name, value in params.items():
                if isinstance(value, str):
                    groups.setdefault((key, name), []).append((item, value))
    slow = pytest.mark.slow
    for cases in groups.values():
        if set(SEQS) <= {value for _, value in cases}:
            for item, value in cases:
                if value not in FAST_SEQS:
                    item.add_marker(slow)
