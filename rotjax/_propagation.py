"""Attitude propagation: integrating an angular velocity given as a function of time or as
samples (hold, trapezoid, or fourth-order Magnus with Gauss nodes, Iserles & Norsett 1999)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from ._numerics import (
    as_float,
    check_shape,
    cross,
    from_scalar_last,
    like_rank,
    public,
    stack,
    to_scalar_last,
    unstack,
)
from ._quaternion import quat_multiply, quat_normalize, quat_prescaled, quat_renormalize
from ._rates import check_frame, quat_rate
from ._rotvec import rotvec_to_quat

METHODS = ("exponential", "euler", "rk4")

# --- attitude propagation ----------------------------------------------------------------------


def _propagation_args(q, omega, frame, method, methods, name):
    """Validated `(q, omega, out_dtype)` for the integrators (a bad frame or method raises)."""
    (q, w), out_dt = as_float(q, omega)
    check_shape(q, (4,), name)
    check_shape(w, (3,), "omega")
    check_frame(frame)
    if method not in methods:
        raise ValueError(f"method must be one of {methods}, got {method!r}")
    return q, w, out_dt


@public
def integrate_angular_velocity(
    q: ArrayLike,
    omega: ArrayLike,
    dt: ArrayLike,
    frame: str = "body",
    method: str = "exponential",
    scalar_first: bool = False,
) -> Array:
    """One step of attitude propagation with the angular velocity held constant over the step.

    Args:
        q: `(..., 4)` orientation at the start of the step; need not be unit.
        omega: `(..., 3)` angular velocity in `frame` over the step (zero-order hold, as a
            gyro sample); broadcasts against `q`.
        dt: `(...)` step length; broadcasts against `q[..., 0]`. Any sign.
        frame: `"body"` (gyro axes, `q_next = q * dq`) or `"world"`
            (`q_next = dq * q`).
        method:

            * `"exponential"` (default): `dq = exp(omega dt / 2)`, the exact step for a
              constant `omega`. Its Taylor branch at `omega = 0` makes the gradient there
              exact.
            * `"euler"`: `q + dt q'`, renormalised. Because `omega` is constant over the
              step, the renormalised step turns about the exact axis by `2 atan(|omega| dt / 2)`
              instead of `|omega| dt`: local error `O(dt^3)`, global `O(dt^2)`.
            * `"rk4"`: classical Runge-Kutta on `q' = q * (omega, 0) / 2`, renormalised:
              local error `O(dt^5)`, global `O(dt^4)`.
        scalar_first: quaternions are `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion at the end of the step, in the layout of `q`. No
            hemisphere is imposed, so a sequence of steps stays continuous.

    Note:
        The step is a pure function of its arrays, so it scans over a gyro log::

            step = lambda q, w: (integrate_angular_velocity(q, w, dt),) * 2
            q_end, q_traj = jax.lax.scan(step, q0, omegas)

        Holding each sample makes the result first order in the sample interval, whatever the
        method: `"rk4"` integrates the held signal accurately, not the motion between the
        samples. For a log of samples,
        [`integrate_angular_velocity_samples`][rotjax.integrate_angular_velocity_samples] reads
        `omega` between them (second or fourth order).

    Examples:
        ```python
        import jax
        import rotjax as rj

        def step(q, _):
            return rj.integrate_angular_velocity(q, [0.0, 0.0, 1.0], 0.1), None

        q, _ = jax.lax.scan(step, rj.rotvec_to_quaternion([0.0, 0.0, 0.0]), length=10)
        print(rj.quaternion_to_rotvec(q).round(6))  # 1 rad/s for 1 s
        # [0. 0. 1.]
        ```
    """
    q, w, out_dt = _propagation_args(q, omega, frame, method, METHODS, "q")
    h = like_rank(jnp.asarray(dt).astype(q.dtype)[..., None], q)
    q = quat_prescaled(to_scalar_last(q, scalar_first))  # q_next is then of order 1 too
    if method == "exponential":
        dq = rotvec_to_quat(w * h)
        q_next = quat_multiply(q, dq) if frame == "body" else quat_multiply(dq, q)
    else:
        # Euler's step and classical Runge-Kutta on the components (per-rotation arrays): each
        # stage reads the parts of the one before, not slices of a stacked sum, which XLA
        # copied one by one in loops of their own.
        hs, qs = h, unstack(q)

        def f(parts):
            return unstack(quat_rate(stack(parts), w, frame))

        def stage(k, c):
            return [x + (c * hs) * y for x, y in zip(qs, k, strict=True)]

        k1 = f(qs)
        if method == "euler":
            q_next = stack(stage(k1, 1.0))
        else:
            k2 = f(stage(k1, 0.5))
            k3 = f(stage(k2, 0.5))
            k4 = f(stage(k3, 1.0))
            ks = zip(qs, k1, k2, k3, k4, strict=True)
            q_next = stack([x + hs / 6 * (a + 2 * b + 2 * c + d) for x, a, b, c, d in ks])
    return from_scalar_last(quat_renormalize(q_next), scalar_first).astype(out_dt)


# --- attitude from sampled angular velocity ----------------------------------------------------

SAMPLE_METHODS = ("hold", "trapezoid", "magnus4")

# Gauss-Legendre nodes of the two-point rule on [0, 1] (Magnus 4: Iserles & Norsett 1999).
_GAUSS = (0.5 - np.sqrt(3.0) / 6.0, 0.5 + np.sqrt(3.0) / 6.0)


def _gauss_weights(n_samples: int):
    """Lagrange weights that interpolate the two Gauss nodes of each step from samples.

    Step `k` (from sample `k` to `k + 1`) uses `p = min(4, n_samples)` consecutive
    samples starting at `s_k = clip(k - 1, 0, n_samples - p)`: centred (a cubic through
    `k - 1 .. k + 2`) inside, one-sided at the two ends. Returns the start indices `(T,)`
    and the weights `(T, 2, p)` in float64.
    """
    p = min(4, n_samples)
    k = np.arange(n_samples - 1)
    start = np.clip(k - 1, 0, n_samples - p)
    nodes = (k - start)[:, None] + np.asarray(_GAUSS)[None, :]  # (T, 2), stencil coordinates
    x = np.arange(p, dtype=np.float64)
    w = np.ones(nodes.shape + (p,))
    for j in range(p):
        for m in range(p):
            if m != j:
                w[..., j] *= (nodes - x[m]) / (x[j] - x[m])
    return start, w


def _step_rotvecs(w, h, frame, method):
    """Rotation vectors `phi_k` of the steps, `q_{k+1} = q_k exp(phi_k)` (body) or
    `exp(phi_k) q_k` (world); `w` is `(T + 1, ..., 3)`, `h` broadcasts against it."""
    # Magnus series of q' = q (w, 0) / 2 (body) or (w, 0) q / 2 (world). For two samples
    # a (earlier) and b (later) the commutator term is the body-frame coning correction
    # + c h^2 (a x b) (Bortz's phi' = w + phi x w / 2), and its mirror - c h^2 (a x b) in the
    # world frame, where the composition order flips.
    sign = 1.0 if frame == "body" else -1.0
    if method == "hold":
        return h * w[:-1]
    if method == "trapezoid":
        # w linear between samples: exact Magnus terms up to order 2 give c = 1/12.
        a, b = w[:-1], w[1:]
        return h * (a + b) / 2 + (sign / 12) * h * h * cross(a, b)
    start, weights = _gauss_weights(w.shape[0])
    wts = jnp.asarray(weights, w.dtype).reshape(weights.shape + (1,) * (w.ndim - 1))
    a = b = jnp.zeros_like(w[:-1])
    for j in range(weights.shape[-1]):  # one gathered copy of the log per stencil point
        wj = w[start + j]
        a = a + wts[:, 0, j] * wj  # w at the first Gauss node
        b = b + wts[:, 1, j] * wj
    # Fourth-order Magnus with Gauss nodes: Omega = h/2 (A1 + A2) + sqrt(3)/12 h^2 [A2, A1].
    return h * (a + b) / 2 + (sign * float(np.sqrt(3.0)) / 12) * h * h * cross(a, b)


@public(time_leading=("omega",))
def integrate_angular_velocity_samples(
    q0: ArrayLike,
    omega: ArrayLike,
    dt: ArrayLike,
    frame: str = "body",
    method: str = "magnus4",
    scalar_first: bool = False,
) -> Array:
    """Attitude history from angular-velocity samples (a gyro log) taken at equal intervals.

    Args:
        q0: `(..., 4)` attitude at the first sample time; need not be unit.
        omega: `(T + 1, ..., 3)` angular velocity in `frame` sampled at `t0 + k dt`,
            `k = 0 .. T` (time on axis 0, batch dimensions after it, broadcasting against
            `q0`), in rad per unit time.
        dt: sample interval, a scalar or `(...)` broadcasting against the batch; any sign.
        frame: `"body"` (gyro axes, `q' = q * (omega, 0) / 2`) or `"world"`
            (`q' = (omega, 0) * q / 2`).
        method: how `omega` is read between samples:

            * `"hold"`: each sample held over the step that follows it, `q_{k+1} =
              q_k exp(omega_k dt)` (the last sample is not used). First order on smooth data.
            * `"trapezoid"`: `omega` linear between samples, with the commutator (coning)
              term; second order.
            * `"magnus4"` (default): fourth-order Magnus step with two Gauss nodes, `omega`
              at the nodes from a cubic through the four nearest samples (one-sided at the
              ends); fourth order. With fewer than four samples the cubic becomes a polynomial
              through all of them.
        scalar_first: quaternions are `(w, x, y, z)`.

    Returns:
        `(T + 1, ..., 4)` unit quaternions at the sample times, in the layout of `q0`; the
            first is `q0` normalised. Consecutive outputs are continuous (no hemisphere is
            imposed).

    Note:
        Each step is an exact rotation (an exponential map, whose Taylor branch keeps values
        and gradients exact at `omega = 0`), so the norm does not drift. The steps are
        composed with `lax.associative_scan`: depth `O(log T)`. The zero `q0` gives NaN;
        a NaN sample affects the attitudes from the steps that read it onwards.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        t = jnp.linspace(0.0, 1.0, 11)  # 11 gyro samples, dt = 0.1
        omega = jnp.stack([jnp.zeros_like(t), jnp.zeros_like(t), 2 * t], axis=-1)
        q = rj.integrate_angular_velocity_samples([0.0, 0.0, 0.0, 1.0], omega, 0.1)
        print(q.shape, rj.quaternion_to_rotvec(q[-1]).round(6))  # angle t^2 at t = 1
        # (11, 4) [0. 0. 1.]
        ```
    """
    q, w, out_dt = _propagation_args(q0, omega, frame, method, SAMPLE_METHODS, "q0")
    if w.ndim < 2:
        raise ValueError(f"omega: expected shape (T + 1, ..., 3), got {tuple(w.shape)}")
    h = jnp.asarray(dt).astype(q.dtype)
    q = quat_normalize(to_scalar_last(q, scalar_first))
    batch = jnp.broadcast_shapes(q.shape[:-1], w.shape[1:-1], h.shape)
    q = jnp.broadcast_to(q, batch + (4,))
    w = jnp.broadcast_to(w, w.shape[:1] + batch + (3,))
    if w.shape[0] == 1:
        return from_scalar_last(q[None], scalar_first).astype(out_dt)
    h = jnp.broadcast_to(h, batch)[None, ..., None]
    dq = rotvec_to_quat(_step_rotvecs(w, h, frame, method))  # (T, ..., 4)
    if frame == "body":  # q_k = q0 dq_0 ... dq_{k-1}
        prods = jax.lax.associative_scan(quat_multiply, dq, axis=0)
        qs = quat_multiply(q[None], prods)
    else:  # q_k = dq_{k-1} ... dq_0 q0
        prods = jax.lax.associative_scan(lambda x, y: quat_multiply(y, x), dq, axis=0)
        qs = quat_multiply(prods, q[None])
    out = jnp.concatenate([q[None], quat_renormalize(qs)], axis=0)
    return from_scalar_last(out, scalar_first).astype(out_dt)
