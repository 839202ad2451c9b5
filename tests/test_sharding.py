"""A batch sharded over two (forced) CPU devices gives the unsharded results and keeps its
sharding, forward and gradient. Runs in a subprocess: the device count is fixed when JAX starts."""

import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent(
    """
    import jax
    import jax.numpy as jnp
    import numpy as np
    from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

    import rotjax as rj

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_numpy_dtype_promotion", "strict")
    jax.config.update("jax_numpy_rank_promotion", "raise")
    assert jax.device_count() == 2, jax.devices()
    mesh = Mesh(np.array(jax.devices()), ("batch",))

    rng = np.random.default_rng(0)
    q = rng.normal(size=(8, 4))
    R = np.asarray(rj.quaternion_to_matrix(q))
    v = rng.normal(size=(8, 3))
    cases = {
        "matrix_to_quaternion": (rj.matrix_to_quaternion, (R,)),
        "quaternion_to_euler": (lambda q: rj.quaternion_to_euler(q, "ZXZ"), (q,)),
        "rotvec_to_matrix": (rj.rotvec_to_matrix, (v,)),
        "quaternion_multiply": (rj.quaternion_multiply, (q, q[::-1])),
    }

    def shard(x):
        spec = P("batch", *([None] * (x.ndim - 1)))
        return jax.device_put(x, NamedSharding(mesh, spec))

    def check(name, got, want):
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-14, atol=1e-14,
                                   err_msg=name)
        spec = got.sharding.spec
        assert not got.sharding.is_fully_replicated and spec and spec[0] == "batch", (name, spec)

    for name, (f, args) in cases.items():
        sharded = [shard(x) for x in args]
        check(name, f(*sharded), f(*args))

        def loss(*a):
            return jnp.sum(f(*a) ** 2)

        # gradients jitted whole: one program each, not one per operation of the loss
        grad = jax.jit(jax.grad(loss, argnums=tuple(range(len(args)))))
        for g, w in zip(grad(*sharded), grad(*args)):
            check(name + " grad", g, w)
        per = jax.jit(jax.vmap(jax.grad(loss, argnums=0)))
        check(name + " vmap(grad)", per(*sharded), per(*args))
        # jit with the sharding as an explicit output constraint: the same values
        jitted = jax.jit(f, out_shardings=NamedSharding(mesh, P("batch")))
        check(name + " jit", jitted(*sharded), f(*args))
    print("ok", len(cases))
    """
)


@pytest.mark.slow  # a subprocess with two host devices, compiling every case
def test_sharded_batch_matches_and_keeps_its_sharding():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ)
    env["XLA_FLAGS"] = env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    env["JAX_PLATFORMS"] = "cpu"
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.strip() == "ok 4"
