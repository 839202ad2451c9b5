"""Program structure, read off the compiled program on the backend at hand (no timing).

Each conversion, and the ``jit(grad)`` of the sum of its outputs, compiles to at most the stated
number of fused loops, reads its inputs and writes its outputs about once (``bytes accessed``
of ``cost_analysis()`` at most ``BYTES_SLACK`` times what they hold, per rotation) and stays
within a stated flop budget per rotation. A change that splits a loop, writes an intermediate
array or reads the input again fails here, on any machine, however noisy.
"""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import rotjax as rj

N = 4096  # rotations per program: structure only; bytes and flops are per rotation
BYTES_SLACK = 1.25
SEQ = "ZYX"

# name: (function, per-rotation argument shapes (the gradient is taken with respect to the
# first), forward (loops, bytes / (inputs + outputs), flops per rotation), and the same for
# jit(grad)). Flop budgets: the float64 count (the larger) rounded up by about 15%.
CASES = {
    "matrix_to_quaternion": (
        rj.matrix_to_quaternion, [(3, 3)], (1, BYTES_SLACK, 180), (1, 1.55, 720)
    ),
    "matrix_to_euler": (
        lambda R: rj.matrix_to_euler(R, SEQ), [(3, 3)], (1, BYTES_SLACK, 500), (3, 3.3, 1020)
    ),
    "quaternion_to_euler": (
        lambda q: rj.quaternion_to_euler(q, SEQ), [(4,)], (2, 1.9, 370), (7, 5.1, 450)
    ),
    "quaternion_to_matrix": (
        rj.quaternion_to_matrix, [(4,)], (1, BYTES_SLACK, 90), (1, BYTES_SLACK, 170)
    ),
    "quaternion_to_rotvec": (
        rj.quaternion_to_rotvec, [(4,)], (1, BYTES_SLACK, 130), (1, BYTES_SLACK, 260)
    ),
    "quaternion_apply": (
        rj.quaternion_apply, [(4,), (3,)], (1, BYTES_SLACK, 100), (1, BYTES_SLACK, 170)
    ),
    "quaternion_to_mrp": (
        rj.quaternion_to_mrp, [(4,)], (1, BYTES_SLACK, 100), (1, BYTES_SLACK, 150)
    ),
    "quaternion_inverse": (
        rj.quaternion_inverse, [(4,)], (1, BYTES_SLACK, 75), (1, BYTES_SLACK, 115)
    ),
    "rotvec_to_quaternion": (
        rj.rotvec_to_quaternion, [(3,)], (4, 2.6, 30), (8, 5.6, 75)
    ),
}  # fmt: skip

_FUSION = re.compile(r"^\s*(?:ROOT\s+)?\S+ = \S+ fusion\(", re.MULTILINE)


def _program(f, shapes, dtype):
    args = [jax.ShapeDtypeStruct((N, *s), dtype) for s in shapes]
    compiled = jax.jit(f).lower(*args).compile()
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    return len(_FUSION.findall(compiled.as_text())), cost["bytes accessed"] / N, cost["flops"] / N


def _check(what, program, budget, io_bytes):
    loops, nbytes, flops = program
    max_loops, slack, max_flops = budget
    assert loops <= max_loops, f"{what}: {loops} loops, at most {max_loops} expected"
    assert nbytes <= slack * io_bytes, (
        f"{what}: {nbytes:.1f} bytes per rotation accessed, at most {slack} x {io_bytes:.0f} "
        "(inputs and outputs) expected"
    )
    assert flops <= max_flops, f"{what}: {flops:.0f} flops per rotation, at most {max_flops}"


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", list(CASES))
def test_forward_program_is_one_pass(name, dtype):
    f, shapes, budget, _ = CASES[name]
    item = np.dtype(dtype).itemsize
    out = jax.eval_shape(f, *(jax.ShapeDtypeStruct((N, *s), dtype) for s in shapes))
    io = (sum(int(np.prod(s)) for s in shapes) + out.size // N) * item
    _check(f"{name} {np.dtype(dtype).name}", _program(f, shapes, dtype), budget, io)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", list(CASES))
def test_gradient_program_is_one_pass(name, dtype):
    f, shapes, _, budget = CASES[name]
    item = np.dtype(dtype).itemsize
    g = jax.grad(lambda *a: jnp.sum(f(*a)))
    # reads every argument, writes the cotangent of the first
    io = (sum(int(np.prod(s)) for s in shapes) + int(np.prod(shapes[0]))) * item
    _check(f"jit(grad) of {name} {np.dtype(dtype).name}", _program(g, shapes, dtype), budget, io)
