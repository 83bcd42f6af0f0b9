"""Array helpers every system shares: float64 conversion, parameter fields, dots."""

import equinox as eqx
import jax.numpy as jnp


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
