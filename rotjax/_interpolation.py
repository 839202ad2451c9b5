"""`Slerp` and `RotationSpline`: scipy's interpolators over keyframe `Rotation`s, as pytrees.

Slerp is piecewise geodesic (Shoemake 1985); the spline is scipy's cubic in the rotation
vector relative to each keyframe with continuous angular acceleration.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from ._numerics import jit, matvec, where
from ._quaternion import quaternion_conjugate, quaternion_multiply
from ._rotation import Rotation, float_array, host_value
from ._rotvec import quaternion_to_rotvec, rotvec_to_quaternion
from ._se3 import so3_right_jacobian, so3_right_jacobian_inverse


def _keyframe_times(times, rotations, dim_msg, order_msg):
    """Keyframe times as a 1-D array matching `rotations` (scipy's checks and messages)."""
    if rotations._stored.ndim > 2:
        raise ValueError("Rotations with more than 1 leading dimension are not supported.")
    t = float_array(times, rotations._stored.dtype)
    if t.ndim != 1:
        raise ValueError(dim_msg)
    if t.shape[0] != len(rotations):
        raise ValueError(
            "Expected number of rotations to be equal to number of timestamps given, got "
            f"{len(rotations)} rotations and {t.shape[0]} timestamps."
        )
    host = host_value(times)
    if host is not None and np.any(np.diff(host) <= 0):
        raise ValueError(order_msg)
    return t


@jax.tree_util.register_pytree_node_class
class Slerp:
    """Spherical linear interpolation between keyframe rotations (scipy's and jax.scipy's).

    Between consecutive keyframes the rotation turns at constant angular rate about a fixed
    axis: `r_i * exp(alpha * log(r_i^-1 r_(i+1)))`. A pytree (`times`, `timedelta`,
    `rotations`, `rotvecs`), so it can be built and called under `jit`.

    Args:
        times: `(N,)` strictly increasing keyframe times, `N >= 2`.
        rotations: a `Rotation` of shape `(N,)`.

    Examples:
        ```python
        from rotjax import Rotation, Slerp

        keys = Rotation.from_euler("z", [[0.0], [90.0], [180.0]], degrees=True)
        slerp = Slerp([0.0, 1.0, 3.0], keys)
        print(slerp([0.5, 2.0]).as_euler("ZYX", degrees=True)[:, 0].round(4))
        # [ 45. 135.]
        ```
    """

    __slots__ = ("times", "timedelta", "rotations", "rotvecs")

    def __init__(self, times: ArrayLike, rotations: Rotation):
        if not isinstance(rotations, Rotation):
            raise TypeError("`rotations` must be a `Rotation` instance.")
        if rotations.single or len(rotations) == 1:
            raise ValueError("`rotations` must be a sequence of at least 2 rotations.")
        t = _keyframe_times(
            times,
            rotations,
            f"Expected times to be specified in a 1 dimensional array, got {np.ndim(times)} "
            "dimensions.",
            "Times must be in strictly increasing order.",
        )
        self.times = t
        self.timedelta = jnp.diff(t)
        self.rotations = rotations
        self.rotvecs = (rotations[:-1].inv() * rotations[1:]).as_rotvec()

    @classmethod
    def init(cls, times: ArrayLike, rotations: Rotation) -> Slerp:
        """jax.scipy's constructor: the same as `Slerp(times, rotations)`.

        Args:
            times: `(N,)` strictly increasing keyframe times, `N >= 2`.
            rotations: a `Rotation` of shape `(N,)`.

        Returns:
            The interpolator.

        Examples:
            ```python
            from rotjax import Rotation, Slerp

            slerp = Slerp.init([0.0, 1.0], Rotation.from_rotvec([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
            print(slerp(0.25).as_rotvec().round(6))
            # [0.   0.   0.25]
            ```
        """
        return cls(times, rotations)

    def tree_flatten(self):
        return (self.times, self.timedelta, self.rotations, self.rotvecs), None

    @classmethod
    def tree_unflatten(cls, aux, children):
        s = object.__new__(cls)
        s.times, s.timedelta, s.rotations, s.rotvecs = children
        return s

    def __call__(self, times: ArrayLike) -> Rotation:
        """Interpolated rotations at `times`.

        Args:
            times: scalar (a single rotation) or `(M,)` times within `[times[0], times[-1]]`;
                outside, the result is NaN (ValueError for NumPy input).

        Returns:
            The interpolated rotation(s), single or of batch shape `(M,)`.

        Examples:
            ```python
            from rotjax import Rotation, Slerp

            slerp = Slerp([0.0, 2.0], Rotation.from_rotvec([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
            print(slerp([0.0, 1.0, 2.0]).as_rotvec()[:, 2].round(6))
            # [0.  0.5 1. ]
            ```
        """
        t = float_array(times, self.times.dtype)
        if t.ndim > 1:
            raise ValueError("`times` must be at most 1-dimensional.")
        host = host_value(times)
        # The range is checked on the host only where both the times and the keyframe times
        # are concrete (under jit, or with traced keyframes, out-of-range times give NaN).
        if host is not None and host.size and not isinstance(self.times, jax.core.Tracer):
            lo, hi = np.asarray(self.times)[[0, -1]]  # (indexing first would be traced)
            if np.any(host < lo) or np.any(host > hi):
                raise ValueError(
                    f"Interpolation times must be within the range [{float(lo)}, "
                    f"{float(hi)}], both inclusive."
                )
        return Rotation._raw(
            _slerp_eval(self.times, self.timedelta, self.rotations._quat, self.rotvecs, t),
            unit=True,
        )


@jit
def _slerp_eval(times, timedelta, quat, rotvecs, t):
    n = times.shape[0]
    idx = jnp.clip(jnp.searchsorted(times, t, side="right") - 1, 0, n - 2)
    alpha = (t - times[idx]) / timedelta[idx]
    alpha = where((t < times[0]) | (t > times[-1]), jnp.nan, alpha)
    step = rotvec_to_quaternion(alpha[..., None] * rotvecs[idx])
    return quaternion_multiply(quat[idx], step)


# --- RotationSpline ----------------------------------------------------------------------
#
# On segment i (times t_i .. t_i+1, length h_i) the rotation is R_i exp(phi(tau)) with the
# cubic rotation vector phi(tau) = c3 tau^3 + c2 tau^2 + w_i tau, phi(h_i) = r_i (the relative
# rotation vector to R_i+1) and phi'(h_i) = A(r_i) w_i+1, where w_k is the body angular rate at
# knot k and A(r) maps body rates to rotation-vector rates (its inverse, B(r), is the Jacobian
# of the body rate of exp(r)). Continuity of the angular acceleration at the interior knots,
#   2/h_i B(r_i) w_i + 4 (1/h_i + 1/h_i+1) w_i+1 + 2/h_i+1 A(r_i+1) w_i+2
#       = 6 (r_i / h_i^2 + r_i+1 / h_i+1^2) - N(r_i, A(r_i) w_i+1),
# with N the part of the angular acceleration quadratic in phi', is solved by fixed-point
# iteration on N (scipy's RotationSpline; end rates w_0 = r_0 / h_0 and w_n = r_n-1 / h_n-1).
# B is the right Jacobian of the SO(3) exponential, body_rate = Jr(phi) phi' (Barfoot 2017,
# Sec. 7.1.5), A its inverse, and N(phi, phi') = (d Jr(phi)[phi']) phi', both closed forms.


def _body_rate(phi, phi_dot):
    """Body angular velocity of `exp(phi)` moving at `phi_dot`: `Jr(phi) phi_dot`."""
    return matvec(so3_right_jacobian(phi), phi_dot)


def _quadratic_term(phi, phi_dot):
    """`N(phi, phi_dot)`: the angular acceleration's term quadratic in `phi_dot`."""
    return jax.jvp(lambda p: _body_rate(p, phi_dot), (phi,), (phi_dot,))[1]


_SPLINE_ITERATIONS = 10


@jit
def _spline_coefficients(times, quat):
    h = jnp.diff(times)
    r = quaternion_to_rotvec(quaternion_multiply(quaternion_conjugate(quat[:-1]), quat[1:]))
    # Equal keyframes: exactly 0 (a fused multiply-add leaves an ulp in conj(q) * q), so that a
    # constant attitude has exactly zero rates; the derivative is that of r.
    same = jnp.all(quat[:-1] == quat[1:], axis=-1, keepdims=True)
    r = where(same, r - jax.lax.stop_gradient(r), r)
    n = r.shape[0]  # segments
    w_first, w_last = r[0] / h[0], r[-1] / h[-1]
    B, A = so3_right_jacobian(r), so3_right_jacobian_inverse(r)
    if n == 1:
        w = jnp.stack([w_first, w_last])
    else:
        m = n - 1  # interior knots
        eye = jnp.eye(3, dtype=r.dtype)
        M = jnp.zeros((m, 3, m, 3), r.dtype)
        k = jnp.arange(m)
        M = M.at[k, :, k, :].set((4 * (1 / h[:-1] + 1 / h[1:]))[:, None, None] * eye[None])
        if m > 1:
            M = M.at[k[1:], :, k[:-1], :].set(2 / h[1:-1, None, None] * B[1:-1])
            M = M.at[k[:-1], :, k[1:], :].set(2 / h[1:-1, None, None] * A[1:-1])
        M = M.reshape(3 * m, 3 * m)
        b0 = 6 * (r[:-1] / h[:-1, None] ** 2 + r[1:] / h[1:, None] ** 2)
        b0 = b0.at[0].add(-2 / h[0] * matvec(B[0], w_first))
        b0 = b0.at[-1].add(-2 / h[-1] * matvec(A[-1], w_last))
        w_int = jnp.broadcast_to(r[:-1] / h[:-1, None], (m, 3))  # start: the chord rates

        def step(_, w_int):
            w_end = jnp.concatenate([w_int, w_last[None]])
            rdot = matvec(A, w_end)
            rhs = b0 - _quadratic_term(r[:-1], rdot[:-1])
            return jnp.linalg.solve(M, rhs.reshape(-1)).reshape(m, 3)

        w_int = jax.lax.fori_loop(0, _SPLINE_ITERATIONS, step, w_int)
        w = jnp.concatenate([w_first[None], w_int, w_last[None]])
    rdot = matvec(A, w[1:])
    hh = h[:, None]
    c3 = (-2 * r + hh * w[:-1] + hh * rdot) / hh**3
    c2 = (3 * r - 2 * hh * w[:-1] - hh * rdot) / hh**2
    return c3, c2, w[:-1]


@jax.tree_util.register_pytree_node_class
class RotationSpline:
    """Cubic rotation spline with continuous angular rate and acceleration (scipy's).

    Interpolates keyframe rotations by a cubic in the rotation vector relative to each
    keyframe, with the angular rates at the knots chosen to make the angular acceleration
    continuous (Sec. 4 of the scipy reference; the end rates are those of the end chords).
    Construction and evaluation are jittable (a fixed number of fixed-point iterations and a
    dense linear solve of size `3 (N - 2)`). A pytree.

    Args:
        times: `(N,)` strictly increasing times, `N >= 2`.
        rotations: a `Rotation` of shape `(N,)`.

    Examples:
        ```python
        from rotjax import Rotation, RotationSpline

        keys = Rotation.from_euler("z", [[0.0], [30.0], [90.0], [180.0]], degrees=True)
        spline = RotationSpline([0.0, 1.0, 2.0, 3.0], keys)
        print(spline([1.0, 1.5]).as_euler("ZYX", degrees=True)[:, 0].round(2))
        # [30. 55.]
        ```
    """

    __slots__ = ("times", "rotations", "_coeffs")

    def __init__(self, times: ArrayLike, rotations: Rotation):
        if not isinstance(rotations, Rotation) or rotations.single:
            raise ValueError("`rotations` must be a sequence of rotations.")
        if len(rotations) == 1:
            raise ValueError("`rotations` must contain at least 2 rotations.")
        t = _keyframe_times(
            times,
            rotations,
            "`times` must be 1-dimensional.",
            "Values in `times` must be in a strictly increasing order.",
        )
        self.times = t
        self.rotations = rotations
        self._coeffs = _spline_coefficients(t, rotations._quat)

    def tree_flatten(self):
        return (self.times, self.rotations, self._coeffs), None

    @classmethod
    def tree_unflatten(cls, aux, children):
        s = object.__new__(cls)
        s.times, s.rotations, s._coeffs = children
        return s

    def __call__(self, times: ArrayLike, order: int = 0) -> Rotation | Array:
        """Rotations (`order=0`), angular rates (1, rad/s) or angular accelerations (2).

        Args:
            times: scalar or `(M,)` times; outside the knots the end cubics extrapolate.
            order: 0, 1 or 2.

        Returns:
            A `Rotation` for `order=0`; else `(..., 3)` angular rates or accelerations: the
                angular velocity of `R(t)` expressed in the frame of the keyframe `R_i` that
                starts the segment (scipy's convention), and its time derivative.

        Examples:
            ```python
            from rotjax import Rotation, RotationSpline

            keys = Rotation.from_euler("z", [[0.0], [90.0], [180.0]], degrees=True)
            spline = RotationSpline([0.0, 1.0, 2.0], keys)  # a steady 90 deg per unit time
            print(spline(0.5, order=1).round(4))
            # [0.     0.     1.5708]
            ```
        """
        if order not in (0, 1, 2):
            raise ValueError("`order` must be 0, 1 or 2.")
        t = float_array(times, self.times.dtype)
        if t.ndim > 1:
            raise ValueError("`times` must be at most 1-dimensional.")
        out = _spline_eval(self.times, self.rotations._quat, self._coeffs, t, order)
        return Rotation._raw(out, unit=True) if order == 0 else out


@jit(static_argnames="order")
def _spline_eval(times, quat, coeffs, t, order):
    c3, c2, c1 = coeffs
    idx = jnp.clip(jnp.searchsorted(times, t, side="right") - 1, 0, times.shape[0] - 2)

    def phi(tau):
        return ((c3[idx] * tau[..., None] + c2[idx]) * tau[..., None] + c1[idx]) * tau[..., None]

    tau = t - times[idx]
    if order == 0:
        return quaternion_multiply(quat[idx], rotvec_to_quaternion(phi(tau)))

    def rate(tau):
        p, pdot = jax.jvp(phi, (tau,), (jnp.ones_like(tau),))
        return _body_rate(p, pdot)

    if order == 1:
        return rate(tau)
    return jax.jvp(rate, (tau,), (jnp.ones_like(tau),))[1]
