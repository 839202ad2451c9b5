"""Strict test environment: float64 enabled, strict dtype promotion, no implicit rank promotion
(JAX's own test setting: a constant of shape ``(4,)`` must not broadcast silently against a
``(..., 4)`` batch), a deadline-free profile."""

import jax
import numpy as np
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")

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
