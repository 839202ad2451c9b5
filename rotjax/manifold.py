"""Steps on the group for gradient-based fitting: right perturbations of rotations and rigid
transforms inside any pytree.

A pytree of parameters may hold [`Rotation`][rotjax.Rotation] and
[`RigidTransform`][rotjax.RigidTransform] objects next to ordinary arrays. Each group element
`x` gets a tangent vector `d` in its body frame, with

* `rplus(x, d) = x * exp(d)`: `Rotation.from_rotvec(d)` (`d` of shape `(*x.shape, 3)`)
  or `RigidTransform.from_exp_coords(d)` (`(*x.shape, 6)`, `[rotvec, v]`);
* `rminus(a, b) = log(a^-1 * b)`, so that `rplus(a, rminus(a, b)) == b`;

and every other leaf is Euclidean (`x + d` and `b - a`). [`grad`][rotjax.manifold.grad]
returns the derivative of `f(rplus(x, d))` in `d` at `d = 0`: a pytree shaped like
[`zero_tangents`][rotjax.manifold.zero_tangents], which any optimiser on arrays (optax's,
for one) can update, and [`rplus`][rotjax.manifold.rplus] applies:

```python
tangents = manifold.grad(loss)(params)
updates, state = optimizer.update(tangents, state)
params = manifold.rplus(params, updates)
```
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from ._rigid import RigidTransform
from ._rotation import Rotation

__all__ = ["grad", "rminus", "rplus", "value_and_grad", "zero_tangents"]


def _is_group(x) -> bool:
    return isinstance(x, (Rotation, RigidTransform))


def _kind(x) -> str:
    return f"a {type(x).__name__}" if _is_group(x) else "an array"


def _check_kind(x, y, what: str) -> None:
    """`TypeError` unless `y` is what `x` needs: the same group class, or an array."""
    if _is_group(y) if not _is_group(x) else type(y) is not type(x):
        raise TypeError(f"{what}: expected {_kind(x)} (as in the first argument), got {_kind(y)}")


def _dim(x) -> int:
    return 3 if isinstance(x, Rotation) else 6


def _dtype(x):
    return jnp.result_type(jax.tree.leaves(x)[0])


def _map(fun, tree, *rest):
    return jax.tree.map(fun, tree, *rest, is_leaf=_is_group)


def zero_tangents(x: Any) -> Any:
    """Zero tangent vectors for every element of the pytree `x`.

    Args:
        x: a pytree whose leaves are [`Rotation`][rotjax.Rotation],
            [`RigidTransform`][rotjax.RigidTransform] or arrays.

    Returns:
        The same structure with `zeros((*leaf.shape, 3))` for a `Rotation`,
            `zeros((*leaf.shape, 6))` for a `RigidTransform` (in their dtype) and
            `zeros_like(leaf)` for an array.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj
        from rotjax import manifold

        params = {"pose": rj.RigidTransform.identity(), "R": rj.Rotation.identity(2),
                  "s": jnp.ones(4)}
        print({k: v.shape for k, v in manifold.zero_tangents(params).items()})
        # {'R': (2, 3), 'pose': (6,), 's': (4,)}
        ```
    """

    def zero(leaf):
        if _is_group(leaf):
            return jnp.zeros((*leaf.shape, _dim(leaf)), _dtype(leaf))
        return jnp.zeros_like(leaf)

    return _map(zero, x)


def rplus(x: Any, delta: Any) -> Any:
    """Right perturbation `x (+) delta = x * exp(delta)`, leaf by leaf.

    Args:
        x: a pytree whose leaves are [`Rotation`][rotjax.Rotation],
            [`RigidTransform`][rotjax.RigidTransform] or arrays.
        delta: tangent vectors shaped like `zero_tangents(x)`: `(*x.shape, 3)` rotation vectors
            for a `Rotation`, `(*x.shape, 6)` exponential coordinates `[rotvec, v]` for a
            `RigidTransform` (both in the element's own frame), and increments for arrays.

    Returns:
        A pytree like `x`: `x * Rotation.from_rotvec(d)`,
            `x * RigidTransform.from_exp_coords(d)`, or `x + d`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj
        from rotjax import manifold

        R = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, 0.5]))
        R2 = manifold.rplus(R, jnp.array([0.0, 0.0, 0.25]))
        print(round(float(R2.as_rotvec()[2]), 3))  # about z by 0.5 + 0.25
        # 0.75
        ```
    """

    def plus(leaf, d):
        if _is_group(d):
            raise TypeError(f"rplus: expected a tangent array for {_kind(leaf)}, got {_kind(d)}")
        if isinstance(leaf, Rotation):
            return leaf * Rotation.from_rotvec(d)
        if _is_group(leaf):
            return leaf * RigidTransform.from_exp_coords(d)
        return leaf + d

    return _map(plus, x, delta)


def rminus(a: Any, b: Any) -> Any:
    """Right difference `log(a^-1 * b)`, leaf by leaf: the tangent that takes `a` to `b`.

    Args:
        a: a pytree whose leaves are [`Rotation`][rotjax.Rotation],
            [`RigidTransform`][rotjax.RigidTransform] or arrays.
        b: a pytree of the same structure.

    Returns:
        Tangents shaped like `zero_tangents(a)` with `rplus(a, rminus(a, b)) == b`: the
            rotation vector of `a.inv() * b` (angle in `[0, pi]`), the exponential coordinates
            of `a.inv() * b`, or `b - a`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj
        from rotjax import manifold

        a = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, 0.5]))
        b = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, 0.75]))
        print(manifold.rminus(a, b).round(3))
        # [0.   0.   0.25]
        ```
    """

    def minus(x, y):
        _check_kind(x, y, "rminus")
        if isinstance(x, Rotation):
            return (x.inv() * y).as_rotvec()
        if _is_group(x):
            return (x.inv() * y).as_exp_coords()
        return y - x

    return _map(minus, a, b)


def _on_tangents(fun, argnums):
    """The differentiated positions, and ``args -> (g, zeros)``: ``fun`` as a function ``g`` of
    the tangents at those arguments, and the zero tangents to evaluate it at."""
    nums = (argnums,) if isinstance(argnums, int) else tuple(argnums)

    def at(args):
        points = [args[i] for i in nums]

        def g(*deltas):
            moved = list(args)
            for i, x, d in zip(nums, points, deltas, strict=True):
                moved[i] = rplus(x, d)
            return fun(*moved)

        return g, tuple(zero_tangents(x) for x in points)

    return nums, at


def value_and_grad(
    fun: Callable, argnums: int | tuple[int, ...] = 0, has_aux: bool = False
) -> Callable:
    """`jax.value_and_grad` on the group: the derivative of `fun` along right perturbations of
    its group-valued arguments.

    Args:
        fun: a function of pytrees whose leaves are [`Rotation`][rotjax.Rotation],
            [`RigidTransform`][rotjax.RigidTransform] or arrays, returning a scalar (and
            auxiliary data with `has_aux`).
        argnums: the argument (an int) or arguments (a tuple of ints) to differentiate.
        has_aux: `fun` returns `(value, aux)`.

    Returns:
        A function of `fun`'s arguments returning `(value, tangent_gradient)`
            (`((value, aux), tangent_gradient)` with `has_aux`), where the gradient is
            `d fun(rplus(x, d)) / d d` at `d = 0`, shaped like `zero_tangents(x)` (a tuple of
            them for a tuple `argnums`).

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj
        from rotjax import manifold

        x, y = jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0])

        def loss(R):  # half the squared distance of R x from y
            return 0.5 * jnp.sum((R.apply(x) - y) ** 2)

        value, g = manifold.value_and_grad(loss)(rj.Rotation.identity())
        print(value, g)
        # 1.0 [ 0.  0. -1.]
        ```
    """
    nums, at = _on_tangents(fun, argnums)

    def wrapped(*args):
        g, zeros = at(args)
        value, grads = jax.value_and_grad(g, argnums=tuple(range(len(nums))), has_aux=has_aux)(
            *zeros
        )
        return value, (grads[0] if isinstance(argnums, int) else grads)

    return wrapped


def grad(fun: Callable, argnums: int | tuple[int, ...] = 0, has_aux: bool = False) -> Callable:
    """`jax.grad` on the group: the tangent-space gradient `d fun(rplus(x, d)) / d d` at `d = 0`.

    Args:
        fun: a function of pytrees whose leaves are [`Rotation`][rotjax.Rotation],
            [`RigidTransform`][rotjax.RigidTransform] or arrays, returning a scalar (and
            auxiliary data with `has_aux`).
        argnums: the argument (an int) or arguments (a tuple of ints) to differentiate.
        has_aux: `fun` returns `(value, aux)`; the gradient function then returns
            `(gradient, aux)`.

    Returns:
        A function of `fun`'s arguments returning the gradient, shaped like
            `zero_tangents(x)` (a tuple of them for a tuple `argnums`). For a `Rotation` it is
            the body-frame gradient: `f(x * exp(d)) = f(x) + <grad, d> + O(|d|^2)`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj
        from rotjax import manifold

        target = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, 1.0]))

        def loss(R):  # half the squared geodesic distance to target
            return 0.5 * jnp.sum(manifold.rminus(R, target) ** 2)

        R = rj.Rotation.identity()
        for _ in range(3):  # gradient steps on the group: each halves the angle
            R = manifold.rplus(R, -0.5 * manifold.grad(loss)(R))
        print(round(float(R.as_rotvec()[2]), 3))
        # 0.875
        ```
    """
    vg = value_and_grad(fun, argnums, has_aux)

    def wrapped(*args):
        value, grads = vg(*args)
        return (grads, value[1]) if has_aux else grads

    return wrapped
