"""Array helpers every system shares: float64 conversion, parameter fields, dots,
NumPy stand-ins for small operations on concrete arrays, and static index arrays
read and summed as slices (`take_rows`, `add_rows`)."""

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
    """`x` as a float64 array. A concrete value on the host is converted by NumPy
    and moved in one `device_put` (`jnp.asarray` compiles a small conversion
    program for each shape, tens of milliseconds in every new process)."""
    return as_array(x, np.float64)


def as_array(x, dtype=None):
    """`jnp.asarray(x, dtype)`, with concrete host values (numbers, lists, NumPy
    arrays, JAX arrays on the CPU) converted by NumPy and moved in one
    `device_put`: no conversion program compiled (`f64`)."""
    if (
        isinstance(x, jax.Array)
        and (dtype is None or x.dtype == dtype)
        and not x.weak_type
    ):
        return x
    if not isinstance(x, jax.core.Tracer) and on_host(x):
        try:
            value = np.asarray(x, dtype=dtype)
        except (TypeError, ValueError):  # not numbers: JAX's own error
            return jnp.asarray(x, dtype=dtype)
        if value.dtype.kind in "biufc":
            return jax.device_put(value)
    return jnp.asarray(x, dtype=dtype)


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


# Static index arrays (a network's topology) as slices. XLA keeps a gather or a
# scatter with constant indices as it is: each one ends a fusion (a kernel of its
# own to compile and to launch), while an index array made of arithmetic runs
# (the nodes of a line, in a state ordered for a narrow band: consecutive or
# strided rows; a line's parameter repeated over its segments) reads and writes
# the same rows as strided slices, (interior) pads and concatenations, which fuse.
MAX_RUNS = 4
"""Index arrays of more runs than this stay a gather (for sums, `add_rows`, a
gather of the inverse index). Every fusion
that reads a concatenation of K runs holds the K-way choice: measured on MoorDyn's
decks (docs/lines.md, "Index arrays as slices"), up to 4 runs (a line's nodes
between its end points, a few lines) compiled and ran faster than the gathers,
16 runs (the 11 lines of the tripod deck) compiled three times slower."""


def _runs(idx):
    """`idx` (1-D, static) as arithmetic runs `(position, length, first value,
    step)`, greedily from the left (a run of one has step 1)."""
    runs, p, n = [], 0, idx.shape[0]
    while p < n:
        step = int(idx[p + 1] - idx[p]) if p + 1 < n else 1
        q = p + 2 if p + 1 < n else p + 1
        while q < n and idx[q] - idx[q - 1] == step:
            q += 1
        runs.append((p, q - p, int(idx[p]), step))
        p = q
    return runs


def _run_rows(x, n, first, step):
    """`x[first + step * arange(n)]` as a slice (reversed for a negative step) or
    one row broadcast (step 0)."""
    if step == 0:
        return jnp.broadcast_to(x[first], (n,) + x.shape[1:])
    last = first + step * (n - 1)
    lo, hi = min(first, last), max(first, last)
    rows = x[lo : hi + 1 : abs(step)]
    return rows if step > 0 else rows[::-1]


def take_rows(x, idx):
    """`x[idx]` for a static integer array `idx` (NumPy, non-negative): strided
    slices and broadcast rows where `idx` is a few arithmetic runs (`MAX_RUNS`),
    a gather otherwise."""
    idx = np.asarray(idx)
    runs = _runs(idx)
    if not runs or len(runs) > MAX_RUNS:
        return x[idx]
    parts = [_run_rows(x, n, first, step) for _, n, first, step in runs]
    return parts[0] if len(parts) == 1 else jnp.concatenate(parts, axis=0)


def add_rows(size, idx, v):
    """`zeros((size,) + v.shape[1:]).at[idx].add(v)` for a static integer array
    `idx` (NumPy, non-negative, below `size`). Where `idx` has no repeated value
    the result is `v` with a zero row appended, read at the inverse index (row
    j of the result from the `v` row sent there, else the zero row): slices
    where that inverse index is a few runs (`take_rows`). Repeated values: the
    first occurrences so, plus the rest (fewer) likewise. A gather where an
    inverse index has more runs than `MAX_RUNS`, never a scatter: XLA:CPU runs a
    scatter as a loop over its rows, one dynamic update per row, a gather as one
    fused kernel."""
    idx = np.asarray(idx, dtype=np.int64)
    n = idx.shape[0]
    if n == 0:
        return jnp.zeros((size,) + v.shape[1:], v.dtype)
    first = np.sort(np.unique(idx, return_index=True)[1])
    if first.shape[0] < n:
        rest = np.setdiff1d(np.arange(n), first)
        return add_rows(size, idx[first], take_rows(v, first)) + add_rows(
            size, idx[rest], take_rows(v, rest)
        )
    inv = np.full(size, n)
    inv[idx] = np.arange(n)
    zero = jnp.zeros((1,) + v.shape[1:], v.dtype)
    return take_rows(jnp.concatenate([v, zero], axis=0), inv)
