"""Array helpers every system shares: float64 conversion, parameter fields, dots,
and NumPy stand-ins for small operations on concrete arrays."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int


# Annotations of zero-dimensional arrays (a parameter, a residual, a flag).
FloatScalar = Float[Array, ""]
BoolScalar = Bool[Array, ""]
IntScalar = Int[Array, ""]


def f64(x):
    """`x` as a float64 array."""
    return jnp.asarray(x, dtype=jnp.float64)


def param(**kw):
    """An `eqx.field` whose value is converted to a float64 array (a physical
    parameter: traced, differentiable, vmappable)."""
    return eqx.field(converter=f64, **kw)


def dot(a, b):
    """Row-wise dot product over the last axis."""
    return jnp.sum(a * b, axis=-1)


def on_host(x) -> bool:
    """Whether `x` is a concrete array in the host's memory: a NumPy array or
    number, or a JAX array on CPU devices only, fully addressable (not a tracer)."""
    if isinstance(x, jax.core.Tracer):
        return False
    if isinstance(x, jax.Array):
        return x.is_fully_addressable and all(d.platform == "cpu" for d in x.devices())
    return True


def host_op(op, *arrays):
    """`op(xp, *arrays)` with `xp` NumPy, as a JAX array, where every array is on
    the host (`on_host`); with `xp` `jax.numpy` on the arrays as they are
    otherwise (tracers, arrays on an accelerator).

    For the small steps around a compiled solve (slicing rows, padding save times,
    comparing a status code): run eagerly by JAX, each distinct operation and
    shape compiles a program of its own, tens of milliseconds in every new
    process, which is most of a second call's time once the solve's own program
    is cached. NumPy's results are the same."""
    if not all(on_host(a) for a in arrays):
        return op(jnp, *arrays)
    out = op(np, *(np.asarray(a) for a in arrays))
    return jax.device_put(out, _first_device(arrays))


def _first_device(arrays):
    """The device of the first JAX array among `arrays` (None: JAX's default),
    where host results go back (`jnp.asarray` would compile a small program of
    its own; `device_put` copies)."""
    return next(
        (next(iter(a.devices())) for a in arrays if isinstance(a, jax.Array)), None
    )


def host_map(op, tree):
    """`op(xp, x)` on every array leaf `x` of `tree`, as `host_op` does for one
    array; where every leaf is on the host, the results go to the device in one
    `device_put` (one transfer call for the whole tree, not one per leaf)."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    if not all(on_host(x) for x in leaves):
        return jax.tree_util.tree_unflatten(treedef, [op(jnp, x) for x in leaves])
    out = [op(np, np.asarray(x)) for x in leaves]
    return jax.tree_util.tree_unflatten(
        treedef, jax.device_put(out, _first_device(leaves))
    )
