"""Program structure, read off the compiled program on the backend at hand (no timing).

Each conversion, and its reverse-mode derivative (``vjp`` of a cotangent read from memory),
compiles to at most the stated number of fused loops, reads its inputs and writes its outputs
about once (``bytes accessed`` of ``cost_analysis()`` at most ``BYTES_SLACK`` times what they
hold, per rotation) and stays within a stated flop budget per rotation. A change that splits a
loop, writes an intermediate array or reads the input again fails here, on any machine, however
noisy. On CPU, each forward loop must also be vectorised (SIMD instructions in its LLVM code,
read from XLA's dump).
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import rotjax as rj
from rotjax import manifold

N = 4096  # rotations per program: structure only; bytes and flops are per rotation
BYTES_SLACK = 1.25
SEQ = "ZYX"

# name: (function, per-rotation argument shapes (the gradient is taken with respect to the
# first), forward (loops, bytes / (inputs + outputs), flops per rotation), and the same for
# jit(grad)). Flop budgets: the float64 count (the larger) rounded up by about 15%. The Euler
# extractions compute each angle from the whole quaternion (see rotjax._numerics.spread): about
# three times the per-rotation flops, in one vectorised loop that runs faster. So does
# rotvec_to_matrix each of its nine entries on the CPU (rotjax._rotvec._exp_matrix_slots): XLA
# counts nine times the shared terms, which its loop nest computes once per rotation.
CASES = {
    "matrix_to_quaternion": (
        rj.matrix_to_quaternion, [(3, 3)], (1, BYTES_SLACK, 180), (1, BYTES_SLACK, 470)
    ),
    "matrix_to_quaternion_markley": (
        lambda R: rj.matrix_to_quaternion(R, method="markley"), [(3, 3)], (1, BYTES_SLACK, 270),
        (1, BYTES_SLACK, 680),
    ),
    "matrix_to_euler": (
        lambda R: rj.matrix_to_euler(R, SEQ), [(3, 3)], (1, BYTES_SLACK, 925), (1, BYTES_SLACK, 780)
    ),
    "quaternion_to_euler": (
        lambda q: rj.quaternion_to_euler(q, SEQ), [(4,)], (1, BYTES_SLACK, 785),
        (1, BYTES_SLACK, 410),
    ),
    "quaternion_to_matrix": (
        rj.quaternion_to_matrix, [(4,)], (1, BYTES_SLACK, 90), (1, BYTES_SLACK, 225)
    ),
    "quaternion_to_rotvec": (
        rj.quaternion_to_rotvec, [(4,)], (1, BYTES_SLACK, 130), (1, BYTES_SLACK, 260)
    ),
    "quaternion_apply": (
        rj.quaternion_apply, [(4,), (3,)], (1, BYTES_SLACK, 100), (1, BYTES_SLACK, 200)
    ),
    "quaternion_to_mrp": (
        rj.quaternion_to_mrp, [(4,)], (1, BYTES_SLACK, 100), (1, BYTES_SLACK, 175)
    ),
    "quaternion_inverse": (
        rj.quaternion_inverse, [(4,)], (1, BYTES_SLACK, 80), (1, BYTES_SLACK, 145)
    ),
    "rotvec_to_quaternion": (
        rj.rotvec_to_quaternion, [(3,)], (1, BYTES_SLACK, 135), (1, BYTES_SLACK, 210)
    ),
    "euler_to_matrix": (
        lambda a: rj.euler_to_matrix(a, SEQ), [(3,)], (1, BYTES_SLACK, 290), (1, BYTES_SLACK, 420)
    ),
    "rotvec_to_matrix": (
        rj.rotvec_to_matrix, [(3,)], (1, BYTES_SLACK, 1290), (1, BYTES_SLACK, 360)
    ),
    "sixd_to_matrix": (
        rj.sixd_to_matrix, [(6,)], (1, BYTES_SLACK, 240), (1, BYTES_SLACK, 340)
    ),
    "axis_angle_to_quaternion": (
        rj.axis_angle_to_quaternion, [(3,), ()], (1, BYTES_SLACK, 136), (1, BYTES_SLACK, 157)
    ),
    # Two outputs of different shapes: XLA:CPU writes each in a loop of its own, which reads q
    # (the axis takes the angle's NaN from q's bits, not from the angle: a division that both
    # loops read was written in a third).
    "quaternion_to_axis_angle": (
        rj.quaternion_to_axis_angle, [(4,)], (2, 1.55, 330), (1, BYTES_SLACK, 320)
    ),
    "slerp": (
        rj.slerp, [(4,), (4,), ()], (1, BYTES_SLACK, 405), (1, BYTES_SLACK, 755)
    ),
    "euler_rate_matrix": (
        lambda a: rj.euler_rate_matrix(a, SEQ), [(3,)], (1, BYTES_SLACK, 215), (1, BYTES_SLACK, 350)
    ),
    "euler_rates_to_angular_velocity": (
        lambda a, r: rj.euler_rates_to_angular_velocity(a, r, SEQ), [(3,), (3,)],
        (1, BYTES_SLACK, 155), (1, BYTES_SLACK, 355)
    ),
    "euler_accelerations_to_angular_acceleration": (
        lambda a, r, c: rj.euler_accelerations_to_angular_acceleration(a, r, c, SEQ),
        [(3,), (3,), (3,)], (1, BYTES_SLACK, 200), (1, BYTES_SLACK, 435)
    ),
    # The exact inverse divides by the distance to gimbal lock; the quotient, read by two
    # components, is a division, which XLA computes in a loop of its own (reading the input).
    "angular_velocity_to_euler_rates": (
        lambda a, w: rj.angular_velocity_to_euler_rates(a, w, SEQ), [(3,), (3,)],
        (2, 1.7, 255), (4, 2.1, 560)
    ),
    "angular_acceleration_to_euler_accelerations": (
        lambda a, r, c: rj.angular_acceleration_to_euler_accelerations(a, r, c, SEQ),
        [(3,), (3,), (3,)], (2, 1.8, 480), (4, 2.1, 1085)
    ),
    "so3_right_jacobian": (
        rj.so3_right_jacobian, [(3,)], (1, BYTES_SLACK, 295), (1, BYTES_SLACK, 495)
    ),
    "so3_left_jacobian_inverse": (
        rj.so3_left_jacobian_inverse, [(3,)], (1, BYTES_SLACK, 330), (1, BYTES_SLACK, 530)
    ),
    "integrate_angular_velocity_euler": (
        lambda q, w: rj.integrate_angular_velocity(q, w, 0.01, method="euler"), [(4,), (3,)],
        (1, BYTES_SLACK, 125), (1, BYTES_SLACK, 220)
    ),
    "integrate_angular_velocity_rk4": (
        lambda q, w: rj.integrate_angular_velocity(q, w, 0.01, method="rk4"), [(4,), (3,)],
        (1, BYTES_SLACK, 270), (1, BYTES_SLACK, 540)
    ),
    # The SE(3) Jacobians: each component of the tangent is read by all 36 entries, more than
    # XLA fuses; it and two coefficients are written per rotation in small loops of their own.
    "se3_left_jacobian": (
        rj.se3_left_jacobian, [(6,)], (7, 1.45, 2130), (1, BYTES_SLACK, 1405)
    ),
    "se3_right_jacobian": (
        rj.se3_right_jacobian, [(6,)], (7, 1.45, 2130), (1, BYTES_SLACK, 1405)
    ),
    "se3_left_jacobian_inverse": (
        rj.se3_left_jacobian_inverse, [(6,)], (6, 1.4, 2245), (1, BYTES_SLACK, 1860)
    ),
    "se3_right_jacobian_inverse": (
        rj.se3_right_jacobian_inverse, [(6,)], (6, 1.4, 2245), (1, BYTES_SLACK, 1860)
    ),
    "se3_adjoint": (rj.se3_adjoint, [(4, 4)], (2, BYTES_SLACK, 1505), (1, BYTES_SLACK, 540)),
    "quaternion_derivative_to_angular_velocity": (
        rj.quaternion_derivative_to_angular_velocity, [(4,), (4,)], (1, BYTES_SLACK, 110),
        (1, BYTES_SLACK, 195)
    ),
    "geodesic_distance": (
        rj.geodesic_distance, [(3, 3), (3, 3)], (1, BYTES_SLACK, 210), (1, BYTES_SLACK, 425)
    ),
    "integrate_angular_velocity_exponential": (
        lambda q, w: rj.integrate_angular_velocity(q, w, 0.01), [(4,), (3,)],
        (1, BYTES_SLACK, 240), (1, BYTES_SLACK, 325)
    ),
}  # fmt: skip

_FUSION = re.compile(r"^\s*(?:ROOT\s+)?\S+ = \S+ fusion\(", re.MULTILINE)


# These tests read XLA's optimised program (its fusions, bytes and flops), which XLA's passes
# make before LLVM compiles the loops: they compile with LLVM's optimisation off (about a third
# less compile time), which leaves that program as it is (test_llvm_level_leaves_the_program).
_STRUCTURE_ONLY = {"xla_backend_optimization_level": 0}
_METADATA = re.compile(r", metadata=\{[^}]*\}")
# The source-location tables (a program loaded from the compilation cache keeps the names of
# the test that compiled it first).
_SOURCES = re.compile(r"^FileNames\n.*?^StackFrames\n.*?\n\n", re.DOTALL | re.MULTILINE)


def _without_sources(text):
    return _SOURCES.sub("", _METADATA.sub("", text))


def _args(shapes, dtype):
    return [jax.ShapeDtypeStruct((N, *s), dtype) for s in shapes]


def _compiled(f, shapes, dtype, options=_STRUCTURE_ONLY):
    return jax.jit(f).lower(*_args(shapes, dtype)).compile(options)


def _program(f, shapes, dtype):
    compiled = _compiled(f, shapes, dtype)
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    return len(_FUSION.findall(compiled.as_text())), cost["bytes accessed"] / N, cost["flops"] / N


def _pullback(f, shapes, dtype):
    """``jit(grad)`` as users meet it: the reverse-mode derivative with respect to the first
    argument, of a cotangent read from memory (a constant one, as for the gradient of a sum,
    XLA folds into the program, which can hide a slow derivative), and the cotangent's bytes
    per rotation. Its arguments: the cotangent's leaves, then ``f``'s."""
    out = jax.eval_shape(f, *_args(shapes, dtype))
    tree = jax.tree.structure(out)

    def pull(*args):
        leaves, (x, *rest) = args[: tree.num_leaves], args[tree.num_leaves :]
        return jax.vjp(lambda x: f(x, *rest), x)[1](jax.tree.unflatten(tree, leaves))[0]

    shapes = [o.shape[1:] for o in jax.tree.leaves(out)] + list(shapes)
    return pull, shapes, sum(o.size * o.dtype.itemsize for o in jax.tree.leaves(out)) / N


def _pads(f, shapes, dtype):
    """Pads in the optimised program: the reverse-mode transpose of a slice, which XLA:CPU
    evaluates per element in a branch of its own, computing the whole expression of the slice
    again there (Euler angles read by slices made ``vjp`` of ``from_euler().as_matrix()`` two
    orders of magnitude slower than its forward); :func:`rotjax._numerics.unstack` reads
    components without them."""
    return _compiled(f, shapes, dtype).as_text().count(" pad(")


def test_llvm_level_leaves_the_program():
    """The optimised program these tests read, with LLVM's optimisation off, is the one
    compiled by default: the same text (but for source locations), bytes and flops."""
    f = lambda p, q, v: (rj.Rotation.from_quat(p) * rj.Rotation.from_quat(q)).apply(v)  # noqa: E731
    g = jax.grad(lambda *a: jnp.sum(f(*a)))
    for h in (f, g):
        a, b = (_compiled(h, [(4,), (4,), (3,)], jnp.float32, o) for o in (_STRUCTURE_ONLY, None))
        assert _without_sources(a.as_text()) == _without_sources(b.as_text())
        assert a.cost_analysis() == b.cost_analysis()


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
    io = (sum(int(np.prod(s)) for s in shapes) + sum(o.size for o in jax.tree.leaves(out)) // N)
    io *= item
    _check(f"{name} {np.dtype(dtype).name}", _program(f, shapes, dtype), budget, io)


# XLA:CPU runs a program that it estimates at fewer than this many flops on the calling thread
# and any other on a worker thread, which costs a thread switch per call.
INLINE_FLOPS = 1000


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", list(CASES))
def test_single_rotation_runs_on_the_calling_thread(name, dtype):
    """One call on one rotation (an unbatched argument) is estimated below INLINE_FLOPS, so its
    latency has no thread switch: a form that counts more (rotvec_to_matrix's per-slot one)
    is kept for larger batches."""
    f, shapes, _, _ = CASES[name]
    cost = jax.jit(f).lower(*(jax.ShapeDtypeStruct(s, dtype) for s in shapes)).compile()
    cost = cost.cost_analysis()
    flops = (cost[0] if isinstance(cost, (list, tuple)) else cost)["flops"]
    assert flops < INLINE_FLOPS, f"{name} {np.dtype(dtype).name}: {flops:.0f} flops for one call"


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", list(CASES))
def test_gradient_program_is_one_pass(name, dtype):
    f, shapes, _, budget = CASES[name]
    item = np.dtype(dtype).itemsize
    g, g_shapes, w_bytes = _pullback(f, shapes, dtype)
    # reads the cotangent and every argument, writes the cotangent of the first
    io = (sum(int(np.prod(s)) for s in shapes) + int(np.prod(shapes[0]))) * item + w_bytes
    what = f"vjp of {name} {np.dtype(dtype).name}"
    _check(what, _program(g, g_shapes, dtype), budget, io)
    assert _pads(g, g_shapes, dtype) == 0, f"{what}: a pad (a slice's transpose)"


# The projecting conversions (the elementwise eigen kernel): many loops forward (the Jacobi
# sweeps), but the reverse mode adds only the derivative rule's few, and reads and writes little
# more than the forward. Its tangents are per-rotation components (rotjax._eigen._top_parts):
# a stacked tangent, read back by the caller, became in reverse mode a select and a reduction
# per component, each a loop computing the whole incoming cotangent again (the vjp of
# RigidTransform.from_matrix(T).as_exp_coords() had 35 loops more than its forward and 2.7x its
# bytes).
PROJECTING = {
    "matrix_to_quaternion optimal": (
        lambda R: rj.matrix_to_quaternion(R, method="optimal"), [(3, 3)]
    ),
    "Rotation.from_matrix": (lambda R: rj.Rotation.from_matrix(R).as_quat(), [(3, 3)]),
    "nined_to_matrix": (rj.nined_to_matrix, [(9,)]),
    "RigidTransform.from_matrix().as_exp_coords()": (
        lambda T: rj.RigidTransform.from_matrix(T).as_exp_coords(), [(4, 4)]
    ),
}
PROJECTING_LOOPS, PROJECTING_BYTES = 10, 1.5


def _assert_gradient_adds_at_most(name, f, shapes, dtype, extra_loops, byte_ratio):
    """The vjp of ``f`` has at most ``extra_loops`` loops more than its forward, and accesses at
    most ``byte_ratio`` times the forward's bytes."""
    loops, nbytes, _ = _program(f, shapes, dtype)
    g, g_shapes, _ = _pullback(f, shapes, dtype)
    g_loops, g_bytes, _ = _program(g, g_shapes, dtype)
    what = f"vjp of {name} {np.dtype(dtype).name}"
    assert g_loops <= loops + extra_loops, f"{what}: {g_loops} loops, forward {loops}"
    assert g_bytes <= byte_ratio * nbytes, f"{what}: {g_bytes:.0f} bytes, forward {nbytes:.0f}"


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", list(PROJECTING))
def test_projection_gradient_adds_little(name, dtype):
    f, shapes = PROJECTING[name]
    _assert_gradient_adds_at_most(name, f, shapes, dtype, PROJECTING_LOOPS, PROJECTING_BYTES)


@pytest.mark.slow
@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", list(PROJECTING))
def test_projection_writes_its_result_in_place(name, dtype):
    """The kernel's quaternion is written in its layout by the loop that computes it: no
    transpose and no copy. Stacked on a leading axis and transposed, it was a concatenate, whose
    four branches LLVM compiled separately, each with its own copy of the extraction."""
    f, shapes = PROJECTING[name]
    text = _compiled(f, shapes, dtype).as_text()
    for op in ("transpose", "copy"):
        assert f" {op}(" not in text, f"{name} {np.dtype(dtype).name}: a {op}"


# The fitting problems: the eigenvector of a sum over a set. The rule writes its intermediate
# tangent once (rotjax._numerics.shared_tangent); left as expressions, its cotangent was computed
# again in the loop of each entry of the summed matrix. Loops added and bytes against the forward.
SUMMED = {
    "quaternion_mean": (rj.quaternion_mean, [(8, 4)], 52, 3.0),
    "align_vectors": (rj.align_vectors, [(8, 3), (8, 3)], 27, 1.85),
}


@pytest.mark.slow
@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", list(SUMMED))
def test_summed_eigenvector_gradient_adds_little(name, dtype):
    f, shapes, extra_loops, byte_ratio = SUMMED[name]
    _assert_gradient_adds_at_most(name, f, shapes, dtype, extra_loops, byte_ratio)


_DUMP_SCRIPT = """
import sys
import jax
import jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
sys.path.insert(0, sys.argv[1])
import test_program as T
T.N = 1 << 20  # the size the benchmark runs: XLA:CPU splits and vectorises loops by size
for name, (f, shapes, _, _) in T.CASES.items():
    for dtype in (jnp.float32, jnp.float64):
        for mode in ("forward", "gradient"):
            h, h_shapes = (f, shapes) if mode == "forward" else T._pullback(f, shapes, dtype)[:2]
            g = lambda *a, h=h: h(*a)
            g.__name__ = name + "__" + mode + "__" + jnp.dtype(dtype).name
            jax.jit(g).lower(*T._args(h_shapes, dtype)).compile()
"""

# Loops still without full-width vector arithmetic (8 float32 or 4 float64 lanes), per program:
# XLA:CPU writes a (3, 3) cotangent per rotation in nested scalar loops, and a (3, 3) result
# stacked by a select among its nine entries (stack_matrix) in a loop nest per rotation, also
# scalar (a concatenate of three rows each stacked by a select is vectorised, but XLA:CPU
# leaves it scalar where the rows share longer expressions: rotvec_to_matrix became 7x
# slower). Exact counts: a new such loop fails, and so does one of these improving (then lower
# it here).
NOT_FULL_WIDTH = {
    ("matrix_to_quaternion", "gradient", "float32"): 1,
    ("matrix_to_quaternion", "gradient", "float64"): 1,
    ("matrix_to_quaternion_markley", "gradient", "float32"): 1,
    ("matrix_to_quaternion_markley", "gradient", "float64"): 1,
    ("matrix_to_euler", "gradient", "float32"): 1,
    ("matrix_to_euler", "gradient", "float64"): 1,
    ("euler_to_matrix", "forward", "float32"): 1,
    ("euler_to_matrix", "forward", "float64"): 1,
    ("euler_rate_matrix", "forward", "float32"): 1,
    ("euler_rate_matrix", "forward", "float64"): 1,
    ("so3_right_jacobian", "forward", "float32"): 1,
    ("so3_right_jacobian", "forward", "float64"): 1,
    ("so3_left_jacobian_inverse", "forward", "float32"): 1,
    ("so3_left_jacobian_inverse", "forward", "float64"): 1,
    ("rotvec_to_matrix", "forward", "float32"): 1,
    ("rotvec_to_matrix", "forward", "float64"): 1,
    ("sixd_to_matrix", "forward", "float32"): 1,
    ("sixd_to_matrix", "forward", "float64"): 1,
    ("geodesic_distance", "gradient", "float32"): 1,
    ("geodesic_distance", "gradient", "float64"): 1,
}

_ARITHMETIC = r"= (?:fadd|fsub|fmul|fdiv|fneg|fcmp \w+) (?:\w+ )*"
_FULL_WIDTH = {"float32": "<8 x float>", "float64": "<4 x double>"}


@pytest.mark.slow  # a subprocess compiling every conversion without the cache
@pytest.mark.skipif(jax.default_backend() != "cpu", reason="reads XLA:CPU's LLVM code")
def test_loops_are_vectorised(tmp_path):
    """Every loop of every conversion above and of its jit(grad), in both dtypes, computes with
    full-width vector instructions (LLVM code read from XLA's dump, at 2^20 rotations), except
    those listed above. XLA:CPU emits a scalar or narrow loop where a long per-rotation
    expression sits in one part of a stacked result (see rotjax._numerics.stack), or
    where it calls a function it outlined. Such a loop keeps the loop count, bytes and flops
    of the full-width one, so the budgets above do not see it."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_", "XLA_"))}
    env["XLA_FLAGS"] = f"--xla_dump_to={tmp_path}"  # a fresh compile (no cache), dumped
    subprocess.run(
        [sys.executable, "-c", _DUMP_SCRIPT, str(Path(__file__).parent)], env=env, check=True
    )
    narrow = {}
    for path in tmp_path.glob("*ir-with-opt.ll"):
        found = re.search(r"jit_(\w+?)__(forward|gradient)__(float32|float64)\.", path.name)
        if found:
            text = path.read_text()
            full = text.count(_FULL_WIDTH[found.group(3)])
            arithmetic = len(re.findall(_ARITHMETIC + r"(?:<\d+ x )?(?:float|double)", text))
            key = found.groups()
            narrow[key] = narrow.get(key, 0) + (arithmetic > 0 and full == 0)
    expected = {(n, m, d) for n in CASES for m in ("forward", "gradient") for d in _FULL_WIDTH}
    assert set(narrow) == expected, f"no LLVM code read for {sorted(expected - set(narrow))}"
    wrong = {k: (v, NOT_FULL_WIDTH.get(k, 0)) for k, v in narrow.items()}
    wrong = {k: v for k, v in wrong.items() if v[0] != v[1]}
    assert not wrong, f"loops without full-width vectors, (program): (found, expected): {wrong}"


# --- composition: chains of rotjax operations are one pass --------------------------------
#
# A rotjax operation fed into another, or returned beside a second output, must not write its
# result out and read it back (nor compute it again per component): the compiled program of a
# chain reads its inputs and writes its outputs about once, forward and under jit(grad), like a
# single conversion. Budgets: bytes only (loops and flops follow from the parts).


def _t(q, t):
    return rj.RigidTransform.from_components(t, rj.Rotation.from_quat(q))


def _parts(T):
    t, r = T.as_components()
    return t, r.as_quat()


_FROM = {
    "quat": (rj.Rotation.from_quat, (4,)),
    "matrix": (lambda m: rj.Rotation.from_matrix(m, assume_valid=True), (3, 3)),
    "rotvec": (rj.Rotation.from_rotvec, (3,)),
    "mrp": (rj.Rotation.from_mrp, (3,)),
    "euler": (lambda a: rj.Rotation.from_euler(SEQ, a), (3,)),
}
_AS = {
    "quat": lambda r: r.as_quat(),
    "matrix": lambda r: r.as_matrix(),
    "rotvec": lambda r: r.as_rotvec(),
    "mrp": lambda r: r.as_mrp(),
    "euler": lambda r: r.as_euler(SEQ),
}
COMPOSED = {
    # the object API: every from_X(...).as_Y() pair, the operators and the pose methods
    **{
        f"Rotation.from_{a}().as_{b}()": (lambda x, f=f, g=g: g(f(x)), [s])
        for a, (f, s) in _FROM.items()
        for b, g in _AS.items()
    },
    "Rotation *": (lambda p, q: (rj.Rotation.from_quat(p) * rj.Rotation.from_quat(q)).as_quat(),
                   [(4,), (4,)]),
    "Rotation * of conversions": (
        lambda a, b, v: (rj.Rotation.from_rotvec(a) * rj.Rotation.from_euler(SEQ, b)).apply(v),
        [(3,), (3,), (3,)]),
    "Rotation.inv": (lambda q: rj.Rotation.from_quat(q).inv().as_quat(), [(4,)]),
    "Rotation.apply": (lambda q, v: rj.Rotation.from_quat(q).apply(v), [(4,), (3,)]),
    "Rotation.magnitude": (lambda q: rj.Rotation.from_quat(q).magnitude(), [(4,)]),
    "RigidTransform *": (lambda q1, t1, q2, t2: _parts(_t(q1, t1) * _t(q2, t2)),
                         [(4,), (3,), (4,), (3,)]),
    "RigidTransform.apply": (lambda q, t, v: _t(q, t).apply(v), [(4,), (3,), (3,)]),
    "RigidTransform.inv": (lambda q, t: _parts(_t(q, t).inv()), [(4,), (3,)]),
    "RigidTransform.from_exp_coords": (
        lambda xi: _parts(rj.RigidTransform.from_exp_coords(xi)), [(6,)]),
    "RigidTransform.as_exp_coords": (lambda q, t: _t(q, t).as_exp_coords(), [(4,), (3,)]),
    # the pipelines users write, through the functions and through the objects
    "unit quaternion from rotvec": (
        lambda v: rj.quaternion_normalize(rj.rotvec_to_quaternion(v)), [(3,)]),
    "Euler angles from a matrix": (
        lambda m: rj.Rotation.from_matrix(m, assume_valid=True).as_euler(SEQ), [(3, 3)]),
    "gyro step q * exp(w)": (
        lambda q, w: (rj.Rotation.from_quat(q) * rj.Rotation.from_rotvec(w)).as_quat(),
        [(4,), (3,)]),
    "gyro step, functions": (
        lambda q, w: rj.quaternion_normalize(
            rj.quaternion_multiply(q, rj.rotvec_to_quaternion(w))), [(4,), (3,)]),
    "compose then apply": (
        lambda p, q, v: (rj.Rotation.from_quat(p) * rj.Rotation.from_quat(q)).apply(v),
        [(4,), (4,), (3,)]),
    "relative angle |log(p^-1 q)|": (
        lambda p, q: (rj.Rotation.from_quat(p).inv() * rj.Rotation.from_quat(q)).magnitude(),
        [(4,), (4,)]),
    "Euler angles then apply": (
        lambda a, v: rj.Rotation.from_euler(SEQ, a).apply(v), [(3,), (3,)]),
    "pose compose then apply": (
        lambda q1, t1, q2, t2, v: (_t(q1, t1) * _t(q2, t2)).apply(v),
        [(4,), (3,), (4,), (3,), (3,)]),
    "geodesic loss on a 6D output": (
        lambda x, m: rj.geodesic_distance(rj.sixd_to_matrix(x), m), [(6,), (3, 3)]),
    "chordal loss on a 6D output": (
        lambda x, m: rj.chordal_distance(rj.sixd_to_matrix(x), m), [(6,), (3, 3)]),
    # a conversion returned beside a second output
    "(matrix_to_quaternion(R), 2 t)": (lambda m, t: (rj.matrix_to_quaternion(m), 2 * t),
                                       [(3, 3), (3,)]),
    "(rotvec_to_quaternion(v), 2 t)": (lambda v, t: (rj.rotvec_to_quaternion(v), 2 * t),
                                       [(3,), (3,)]),
    "(quaternion_to_matrix(q), q)": (lambda q: (rj.quaternion_to_matrix(q), q), [(4,)]),
    "matrix_to_rotvec": (rj.matrix_to_rotvec, [(3, 3)]),
    "RigidTransform(m, normalize=False)": (
        lambda m: _parts(rj.RigidTransform(m, normalize=False)), [(4, 4)]),
    "se3_log": (rj.se3_log, [(4, 4)]),
    "se3_exp": (rj.se3_exp, [(6,)]),
    # a power: the exponent times the logarithm's components (an array product of the stacked
    # logarithm is read back by slices, which XLA copies in loops of their own)
    "quaternion_power": (lambda q, n: rj.quaternion_power(q, n), [(4,), ()]),
    "Rotation **": (lambda q: (rj.Rotation.from_quat(q) ** 0.5).as_quat(), [(4,)]),
    "RigidTransform **": (lambda q, t: _parts(_t(q, t) ** 0.5), [(4,), (3,)]),
    # the pose error of SLAM and pose graphs: components of stored arrays are (..., 1) slices,
    # and the chain's sums and negations are taken on components (a slice's squeeze and an
    # array operation on a stacked result each made XLA copy per-rotation values in loops of
    # their own)
    "manifold.rminus of RigidTransforms": (
        lambda q1, t1, q2, t2: manifold.rminus(_t(q1, t1), _t(q2, t2)),
        [(4,), (3,), (4,), (3,)]),
}  # fmt: skip

# Cases above the common slack, with the reason. XLA:CPU materialises the inputs' components
# (a slice each) before a fused loop it judges too large to take them in: quaternion_to_euler's
# gradient (its budget above admits the same), and from_euler's matrix through the quaternion.
# And it writes each output of a program in a loop of its own
# (no multi-output fusion), each reading the inputs it needs: the translation and the rotation
# of a transform read the same matrix or quaternion.
COMPOSED_SLACK = {
    ("Rotation.from_quat().as_euler()", "gradient"): 2.3,
    ("Rotation.from_euler().as_matrix()", "forward"): 1.55,
    ("RigidTransform.inv", "forward"): 1.35,
    ("RigidTransform **", "forward"): 1.35,
    ("RigidTransform(m, normalize=False)", "forward"): 1.7,
    ("RigidTransform(m, normalize=False)", "gradient"): 1.7,
}

# The default tier checks these; the slow tier every case.
_COMPOSED_FAST = {
    "Rotation.from_rotvec().as_quat()",
    "Rotation.from_matrix().as_euler()",
    "gyro step q * exp(w)",
    "pose compose then apply",
    "chordal loss on a 6D output",
    "(matrix_to_quaternion(R), 2 t)",
    "manifold.rminus of RigidTransforms",
    "Rotation **",
}


def _composed_params():
    return [
        pytest.param(n, marks=() if n in _COMPOSED_FAST else pytest.mark.slow) for n in COMPOSED
    ]


def _io_bytes(f, shapes, dtype, grad):
    item = np.dtype(dtype).itemsize
    ins = sum(int(np.prod(s)) for s in shapes) * item
    if grad:  # reads every argument, writes the cotangent of the first
        return ins + int(np.prod(shapes[0])) * item
    out = jax.eval_shape(f, *(jax.ShapeDtypeStruct((N, *s), dtype) for s in shapes))
    return ins + sum(o.size * o.dtype.itemsize for o in jax.tree.leaves(out)) / N


@pytest.mark.parametrize("mode", ["forward", "gradient"])
@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", _composed_params())
def test_composed_program_is_one_pass(name, dtype, mode):
    f, shapes = COMPOSED[name]
    grad = mode == "gradient"
    g, g_shapes, w_bytes = _pullback(f, shapes, dtype) if grad else (f, shapes, 0)
    _, nbytes, _ = _program(g, g_shapes, dtype)
    io = _io_bytes(f, shapes, dtype, grad) + w_bytes
    slack = COMPOSED_SLACK.get((name, mode), BYTES_SLACK)
    assert nbytes <= slack * io, (
        f"{mode} of {name} {np.dtype(dtype).name}: {nbytes:.1f} bytes per rotation accessed, at "
        f"most {slack} x {io:.0f} (inputs and outputs) expected"
    )
    if grad:
        assert _pads(g, g_shapes, dtype) == 0, f"vjp of {name}: a pad (a slice's transpose)"


# A chain of functions against the same chain of objects. A conversion's unit quaternion is
# noted (rotjax._numerics.noted_unit), as a Rotation built by one is marked, so the readers
# after it skip the prescaling (its exact factor is 1) through either API.
FUNCTIONS_AND_OBJECTS = {
    "normalize(rotvec_to_quaternion)": (
        lambda v: rj.quaternion_normalize(rj.rotvec_to_quaternion(v)),
        lambda v: rj.Rotation.from_rotvec(v).as_quat(), [(3,)]),
    "apply(euler_to_quaternion)": (
        lambda a, v: rj.quaternion_apply(rj.euler_to_quaternion(a, SEQ), v),
        lambda a, v: rj.Rotation.from_euler(SEQ, a).apply(v), [(3,), (3,)]),
    "to_rotvec(euler_to_quaternion)": (
        lambda a: rj.quaternion_to_rotvec(rj.euler_to_quaternion(a, SEQ)),
        lambda a: rj.Rotation.from_euler(SEQ, a).as_rotvec(), [(3,)]),
    "rotation_angle(rotvec_to_quaternion)": (
        lambda v: rj.rotation_angle(rj.rotvec_to_quaternion(v)),
        lambda v: rj.Rotation.from_rotvec(v).magnitude(), [(3,)]),
    "to_matrix(multiply(rotvec_to_quaternion, euler_to_quaternion))": (
        lambda a, b: rj.quaternion_to_matrix(
            rj.quaternion_multiply(rj.rotvec_to_quaternion(a), rj.euler_to_quaternion(b, SEQ))),
        lambda a, b: (rj.Rotation.from_rotvec(a) * rj.Rotation.from_euler(SEQ, b)).as_matrix(),
        [(3,), (3,)]),
}  # fmt: skip


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
@pytest.mark.parametrize("name", list(FUNCTIONS_AND_OBJECTS))
def test_function_chain_does_no_more_than_objects(name, dtype):
    functions, objects, shapes = FUNCTIONS_AND_OBJECTS[name]
    f_loops, f_bytes, f_flops = _program(functions, shapes, dtype)
    o_loops, o_bytes, o_flops = _program(objects, shapes, dtype)
    what = f"{name} {np.dtype(dtype).name}"
    assert (f_loops, f_bytes) <= (o_loops, o_bytes), f"{what}: loops and bytes"
    assert f_flops <= o_flops, f"{what}: {f_flops:.0f} flops per rotation, objects {o_flops:.0f}"


# Functions that JAX's lowering itself emits (a cached lowering rule), not a nested jit.
_LOWERING_HELPERS = {"argmax"}


def _nested_functions(f, shapes, dtype):
    text = jax.jit(f).lower(*_args(shapes, dtype)).as_text()
    names = {re.sub(r"_\d+$", "", n) for n in re.findall(r"func\.func \w+ @(\w+)", text)}
    return names - {"main"} - _LOWERING_HELPERS


_PROGRAMS = {
    **{k: (v[0], v[1]) for k, v in CASES.items()},
    **PROJECTING,
    **{k: v[:2] for k, v in SUMMED.items()},
    **COMPOSED,
}


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=() if n in CASES else pytest.mark.slow) for n in _PROGRAMS]
)
def test_program_calls_no_nested_function(name):
    """No program of rotjax calls a function of its own (a nested ``jit``, such as
    ``jnp.where``'s): each is one more function for JAX to trace and lower and for XLA to
    inline, hundreds in a conversion's gradient (see rotjax._numerics.where)."""
    f, shapes = _PROGRAMS[name]
    g, g_shapes, _ = _pullback(f, shapes, jnp.float32)
    for what, h, s in (("forward", f, shapes), ("vjp", g, g_shapes)):
        assert not _nested_functions(h, s, jnp.float32), f"{name} {what}"


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_float32_conversion_has_no_64_bit_integer(name):
    """An integer that selects among float32 values is 32 bits wide, so that its selects share
    the loop's vector lanes (atan2's octant index, a weakly typed int64, slowed
    quaternion_to_euler's float32 loop)."""
    f, shapes, *_ = CASES[name]
    g, g_shapes, _ = _pullback(f, shapes, jnp.float32)
    for what, h, s in (("forward", f, shapes), ("vjp", g, g_shapes)):
        text = _compiled(h, s, jnp.float32).as_text()
        assert not re.search(r"\b[su]64\[", text), f"{name} {what}"
