"""Fuzzing: batches built to find trouble (see ``trouble_batches``) through every public
function, in float32 and float64: finite results for valid input, and the documented bounds
(unit quaternions, orthonormal matrices, angle ranges, round trips within a few eps).

Each function is compiled once per dtype (the batch shape is fixed) and each hypothesis
example feeds it a new batch of 64."""

import jax
import numpy as np
import pytest
from helpers import DTYPES, every_public, public_inputs, sweep, trouble_batches
from hypothesis import given, settings

import rotjax as rj

EXAMPLES = 25
# The public functions in groups (every fourth name, in sorted order: the eigenvector kernels
# fall in different groups), each group a test of its own that xdist can give to either worker:
# every function compiles a program per dtype, and all of them in one test took 40 s. (One
# program for all the functions compiles slower than the functions one by one: XLA's time
# grows faster than the program.) Built from scipy's inputs: nothing is compiled at import.
GROUPS = 4
NAMES = sorted(every_public(*public_inputs(4, np.float64)))


def _rounded_unit(q):
    """The quaternions actually passed (rounded to their dtype), normalised in float64."""
    q = np.asarray(q, np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _rotation_error(q1, q2):
    """Largest component difference between quaternions, up to sign."""
    q1, q2 = np.asarray(q1, np.float64), np.asarray(q2, np.float64)
    return np.minimum(np.abs(q1 - q2).max(-1), np.abs(q1 + q2).max(-1))


@pytest.mark.parametrize("group", range(GROUPS))
@pytest.mark.parametrize("dtype", sweep(DTYPES, fast=[np.float64]), ids=lambda d: d.__name__)
def test_every_public_function_is_finite_on_trouble(dtype, group):
    names = NAMES[group::GROUPS]

    @settings(max_examples=EXAMPLES)
    @given(trouble_batches(dtype))
    def check(batch):
        inputs, _ = batch
        calls = every_public(*inputs)
        assert sorted(calls) == NAMES  # every function is in a group
        for name in names:
            f, args = calls[name]
            # a zero axis (the rotation vector of the identity) is no axis: NaN on purpose
            valid = np.linalg.norm(args[0], axis=-1) > 0 if name.startswith("axis_") else True
            for out in jax.tree.leaves(f(*args)):
                out = np.asarray(out)
                assert out.dtype == dtype, (name, out.dtype)
                bad = ~np.isfinite(out.reshape(out.shape[0], -1)).all(-1) & valid
                assert not bad.any(), (name, np.flatnonzero(bad), [a[bad] for a in args])

    check()


@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: d.__name__)
def test_documented_bounds_and_round_trips_on_trouble(dtype):
    eps = np.finfo(dtype).eps

    @settings(max_examples=EXAMPLES)
    @given(trouble_batches(dtype))
    def check(batch):
        (q, R_noisy, _, _), _ = batch
        unit = _rounded_unit(q)
        # unit quaternions out, whatever the input's scale
        for out in (
            rj.quaternion_normalize(q),
            rj.rotvec_to_quaternion(rj.quaternion_to_rotvec(q)),
        ):
            n = np.linalg.norm(np.asarray(out, np.float64), axis=-1)
            assert np.abs(n - 1).max() <= 4 * eps
        # orthonormal matrices with determinant +1, and back to the same rotation
        R = rj.quaternion_to_matrix(q)
        R64 = np.asarray(R, np.float64)
        gram = np.einsum("nji,njk->nik", R64, R64) - np.eye(3)
        # Entries within 3 eps of the exact matrix (the accuracy sets) move each entry of the
        # Gram matrix, and the determinant, by at most 2 sqrt(3) 3 eps, plus 2 eps for their
        # own evaluation here: 12.4 eps (10.8 eps were seen, in 400k quaternions at every scale).
        bound = (2 * np.sqrt(3) * 3 + 2) * eps
        assert np.abs(gram).max() <= bound and np.abs(np.linalg.det(R64) - 1).max() <= bound
        for method in ("shepperd", "markley", "optimal"):
            err = _rotation_error(rj.matrix_to_quaternion(R, method=method), unit)
            assert err.max() <= 8 * eps, (method, err.max() / eps, q[err.argmax()])
        # rotation vectors: norm in [0, pi], the same rotation back
        v = rj.quaternion_to_rotvec(q)
        norm = np.linalg.norm(np.asarray(v, np.float64), axis=-1)
        assert norm.max() <= np.pi * (1 + 2 * eps)
        assert _rotation_error(rj.rotvec_to_quaternion(v), unit).max() <= 8 * eps
        angle = np.asarray(rj.rotation_angle(q), np.float64)
        assert angle.min() >= 0 and angle.max() <= np.pi * (1 + 2 * eps)
        # Euler angles: in scipy's ranges, and the same rotation back, at gimbal lock included
        for seq in ("ZYX", "zxz", "XYX", "yzx"):
            a = np.asarray(rj.quaternion_to_euler(q, seq), np.float64)
            assert np.abs(a).max() <= np.pi * (1 + 2 * eps)
            lo, hi = (0, np.pi) if seq[0] == seq[2] else (-np.pi / 2, np.pi / 2)
            assert a[:, 1].min() >= lo - 2 * eps and a[:, 1].max() <= hi * (1 + 2 * eps)
            back = rj.euler_to_quaternion(a.astype(dtype), seq)
            err = _rotation_error(back, unit)
            assert err.max() <= 8 * eps, (seq, err.max() / eps, q[err.argmax()])
        # noisy, scaled matrices: still a unit quaternion and Euler angles in range
        for method in ("shepperd", "markley", "optimal"):
            out = np.asarray(rj.matrix_to_quaternion(R_noisy, method=method), np.float64)
            assert np.abs(np.linalg.norm(out, axis=-1) - 1).max() <= 4 * eps, method
        a = np.asarray(rj.matrix_to_euler(R_noisy, "XYZ"), np.float64)
        assert np.abs(a).max() <= np.pi * (1 + 2 * eps)
        assert np.abs(a[:, 1]).max() <= np.pi / 2 * (1 + 2 * eps)

    check()
