"""Newton-matrix linear algebra that exploits the chain structure of strings.

The state of every string and chain model is node-major (one row per node), so the
Jacobian of its vector field is block-banded: the row block of node i depends only on
the nodes i - w .. i + w (w = 1 for all string formulations: displacement, natural
eps-t and eps-phi, where x = -M^{-1} z applies a tridiagonal M^{-1} to z(node)). A
dense Jacobian (``jax.jacfwd``, n JVPs) and a dense LU (O(n^3)) then waste almost
all of their work. This module gives, for a function ``fn: (n, b) -> (n, b)``:

* ``detect_width(fn, y)``: the node bandwidth w, found numerically *at trace time*
  on a surrogate (random inputs of the same shapes): a few unit-column JVPs give a
  candidate w, and two random-direction JVPs verify that the banded reconstruction
  reproduces J v. Anything unexpected (a pytree state, a closure that cannot be
  evaluated eagerly, a wide band) gives ``None``: use the dense path.
* ``block_tridiagonal_jacobian(fn, y, w)``: the Jacobian as a block-tridiagonal
  matrix of super-blocks (w nodes each, block size B = w b) from only 3 B JVPs
  (Curtis-Powell-Reid colouring: columns whose super-blocks are 3 apart never meet
  in a row), never materialising the n x n matrix.
* ``bcr_factor`` / ``bcr_solve``: block cyclic reduction, O(N B^3) work and
  O(log N) sequential depth, fully vectorised over blocks (no ``lax.scan``; the
  levels are unrolled at trace time). It inverts the B x B blocks (``small_inv``:
  closed form up to 4 x 4, pivoted elimination above) and does not pivot across
  blocks: fine for the Newton matrices ``I - h gamma J`` of
  mechanical chains, whose reduced matrices are (scaled) symmetric positive
  definite; ``tests/solvers/test_linalg.py`` checks it against the dense solve.
* ``thomas_factor`` / ``thomas_solve``: the block Thomas algorithm (elimination
  from the first block to the last, one step in a ``lax.scan``): a program of one
  step whatever N. ``block_factor`` / ``block_solve`` use it for blocks of at most
  two rows on the CPU, cyclic reduction otherwise (measured:
  docs/numerics.md, "Banded linear algebra").
* ``SecondOrderFactor``: for a model whose node rows are (q, v) with dq/dt = v
  exactly (declared by ``SolverStructure.second_order``), the Newton matrix
  ``[[a I, b I], [P, Q]]`` is reduced to the velocity unknowns,
  ``S = Q - (b / a) P``: blocks of half the size, 8x fewer block flops and a
  closed-form 2 x 2 inverse in 2D.
* ``BorderedJacobian``: a band with a few leading rows (``border``) coupled to
  every node (a vessel holding the lines of its mooring): the band is factorised
  as above and the border by its Schur complement, from 3 B JVPs for the band
  and ``border b`` JVPs and transposed JVPs for the border's columns and rows.
* ``NewtonFactor``: one interface (``build(fn, y, structure)`` and ``.solve``)
  over the dense and the banded paths, used by the stage Newton iteration, the
  Rosenbrock, BDF, theta and Newmark solvers.
"""

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax
import jax.flatten_util as jfu
import jax.lax as lax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import jax.tree_util as jtu
import numpy as np
from jaxtyping import Array

from .._arrays import add_rows
from .._jit import cpu_compiler_options
from .._lazy import diffrax as dfx
from .._scene import Scene, scene_vector_field


# Below this many unknowns the dense path is as fast (few JVPs either way) and has
# fewer ops to compile.
MIN_BANDED_SIZE = 48
# Use the band only if its colour count 3 w b is well below the number of unknowns.
_MAX_COLOUR_FRACTION = 0.5


# ----------------------------------------------------------------------------
# Structure detection (trace time, on a surrogate)
# ----------------------------------------------------------------------------


def _is_array(x) -> bool:
    return isinstance(x, (jax.Array, np.ndarray, np.generic))


def _surrogate(tree, seed: int):
    """Concrete stand-ins for the array leaves of `tree`: same shapes and dtypes,
    values uniform in [0.5, 1.5] (integers: 0). Structure only matters here."""
    rng = np.random.default_rng(seed)
    leaves, treedef = jtu.tree_flatten(tree)
    out = []
    for x in leaves:
        if _is_array(x) or isinstance(x, jax.core.Tracer):
            dtype = np.dtype(x.dtype)
            if np.issubdtype(dtype, np.inexact):
                v = rng.uniform(0.5, 1.5, size=np.shape(x)).astype(dtype)
            else:
                v = np.zeros(np.shape(x), dtype)
            out.append(jnp.asarray(v))
        else:
            out.append(x)
    return jtu.tree_unflatten(treedef, out)


_WIDTH_CACHE: dict = {}


def _band_probe(fn, W, y, args, v):
    """Band of the Jacobian of `fn(., args)` at `y` assuming node bandwidth <= W
    (colour period 2W + 1), and the error of that band against the exact J v."""
    n, b = y.shape
    q = 2 * W + 1
    seeds = np.zeros((q * b, n, b), dtype=np.dtype(y.dtype))
    for j in range(n):
        for c in range(b):
            seeds[(j % q) * b + c, j, c] = 1.0
    _, lin = jax.linearize(lambda u: fn(u, args), y)
    out = jax.vmap(lin)(jnp.asarray(seeds))  # (q b, n, b): [colour, row node, row comp]
    rows = np.arange(n)[:, None]
    offs = np.arange(-W, W + 1)[None, :]
    cols = rows + offs  # (n, q) column node of each band entry
    inside = (cols >= 0) & (cols < n)
    colour = (np.clip(cols, 0, n - 1) % q)[:, :, None] * b + np.arange(b)  # (n, q, b)
    # band[i, d, r, c] = J[(i, r), (i + d, c)]
    band = out[colour, rows[:, :, None], :]  # (n, q, b_col, b_row)
    band = jnp.where(inside[:, :, None, None], jnp.swapaxes(band, 2, 3), 0.0)
    vcols = jnp.where(inside[:, :, None], v[np.clip(cols, 0, n - 1)], 0.0)
    approx = jnp.einsum("idrc,idc->ir", band, vcols)
    exact = lin(v)
    err = jnp.max(jnp.abs(exact - approx)) / (jnp.max(jnp.abs(exact)) + 1e-300)
    used = jnp.any((band != 0) | ~jnp.isfinite(band), axis=(0, 2, 3))  # (q,)
    return used, err, jnp.all(jnp.isfinite(exact))


def detect_width(fn, y, args=None, max_width: int = 4):
    """Node bandwidth of the Jacobian of `fn(y, args)` w.r.t. `y` (2-d, node-major),
    or None if it is wider than `max_width` or cannot be determined.

    Runs at trace time, eagerly, on surrogate values of the same shapes (so it works
    when `y` and `args` are tracers), assuming the sparsity pattern does not depend
    on the values. The result is cached per jaxpr of `fn`.
    """
    if not (hasattr(y, "shape") and len(y.shape) == 2):
        return None
    n, b = y.shape
    if n < 3:
        return None
    W = min(max_width, n - 1)
    try:
        with jax.ensure_compile_time_eval():
            fs = _surrogate(fn, 1)
            # Non-array leaves (e.g. the jaxprs of closure-converted functions in
            # diffrax's stage arguments) are structure: close over them.
            a_dyn, a_static = eqx.partition(_surrogate(args, 2), eqx.is_array)
            call = lambda u, a: fs(u, eqx.combine(a, a_static))
            y0 = _surrogate(y, 3)
            key = (str(jax.make_jaxpr(call)(y0, a_dyn)), W)
            if key in _WIDTH_CACHE:
                return _WIDTH_CACHE[key]
            inputs = [
                (
                    _surrogate(y, 10 + seed),
                    eqx.filter(_surrogate(args, 20 + seed), eqx.is_array),
                    jnp.asarray(
                        np.random.default_rng(30 + seed).standard_normal((n, b)),
                        y.dtype,
                    ),
                )
                for seed in (0, 1)
            ]
        # Compiled ahead of time and called as a compiled program: traced under
        # compile-time evaluation, each step on the probe's constant index arrays
        # would run (and compile) eagerly, one small program each.
        probe = jax.jit(lambda u, a, v: _band_probe(call, W, u, a, v))
        options = cpu_compiler_options() if jax.default_backend() == "cpu" else None
        compiled = probe.lower(*inputs[0]).compile(options)
        used = np.zeros(2 * W + 1, bool)
        width = None
        for ys, aa, v in inputs:
            u, err, finite = compiled(ys, aa, v)
            if not bool(finite) or float(err) > 1e-8:
                break
            used |= np.asarray(u)
        else:
            offs = np.nonzero(used)[0] - W
            width = max(int(np.max(np.abs(offs))) if offs.size else 0, 1)
        _WIDTH_CACHE[key] = width
        return width
    except Exception:  # noqa: BLE001  (a surrogate we cannot evaluate: go dense)
        return None


def declared_width(fn, y, args=None):
    """The node bandwidth the scene's model declares (`SolverStructure.bandwidth`)
    when exactly one scene is found in `fn` and `args` (the ODE's arguments inside a
    solver's stage relation) and the unknown `y` has the scene's state shape, else
    None. The stage relations of implicit methods (y - c f(y) and the like) have the
    band of the vector field."""
    scene = _declared_scene(fn, y, args)
    return None if scene is None else scene.structure.bandwidth


def _declared_scene(fn, y, args):
    """The one scene in `fn` and `args` whose state has the shape of the 2-d unknown
    `y`, else None."""
    if not (hasattr(y, "shape") and len(y.shape) == 2):
        return None
    is_scene = lambda x: isinstance(x, Scene)
    scenes = [x for x in jtu.tree_leaves((fn, args), is_leaf=is_scene) if is_scene(x)]
    if len(scenes) != 1 or tuple(np.shape(scenes[0].y0)) != tuple(y.shape):
        return None
    return scenes[0]


@dataclasses.dataclass(frozen=True)
class BorderedWidth:
    """The structure of a state whose first `border` rows couple to every row and
    whose other rows form a band of node width `width` (`BorderedJacobian`)."""

    width: int
    border: int
    coupled: tuple = ()
    columns: tuple = ()


def choose_structure(fn, y, args=None, linear_solver: str = "auto"):
    """Return the node bandwidth to use (int), a `BorderedWidth` (a model that
    declares `SolverStructure.border`), or None for the dense path.

    `linear_solver`: "dense", "banded" (raises if no band is found) or "auto"
    (banded for large enough systems with a narrow band). The band is the one the
    scene's model declares (`declared_width`; none for a model that declares its
    Jacobian dense), or else detected by probing (`detect_width`: one trace-time
    compilation per new relation).
    """
    if linear_solver == "dense":
        return None
    scene = _declared_scene(fn, y, args)
    if linear_solver == "auto" and scene is not None and scene.structure.dense:
        return None
    border = 0 if scene is None else int(scene.structure.border)
    if border:
        st = scene.structure
        coupled = tuple(int(r) - border for r in st.border_coupled)
        columns = tuple(int(c) for c in st.border_columns)
        return BorderedWidth(int(st.bandwidth), border, coupled, columns)
    width = declared_width(fn, y, args)
    if width is None:
        width = detect_width(fn, y, args)
    if linear_solver == "banded":
        if width is None:
            raise ValueError(
                "`linear_solver='banded'` needs a node-major state whose Jacobian "
                "is block-banded; none was found. Use 'dense' or 'auto'."
            )
        return width
    if width is None:
        return None
    n, b = y.shape
    size = n * b
    if size < MIN_BANDED_SIZE or 3 * width * b > _MAX_COLOUR_FRACTION * size:
        return None
    return width


# ----------------------------------------------------------------------------
# Block-tridiagonal matrices
# ----------------------------------------------------------------------------


class BlockTridiagonal(eqx.Module):
    """Block-tridiagonal matrix: row block I is
    `lower[I] x[I-1] + diag[I] x[I] + upper[I] x[I+1]` (`lower[0]`, `upper[-1]` = 0).

    Blocks are super-blocks of `width` nodes of the original node-major layout
    (`n` nodes, `b` components each), padded with identity rows to a multiple of
    `width`.
    """

    lower: Array  # (N, B, B)
    diag: Array
    upper: Array
    n: int = eqx.field(static=True)
    b: int = eqx.field(static=True)
    width: int = eqx.field(static=True)
    # d > 0: node rows are (q, v), d components each, and the matrix is
    # a I + b J of a vector field with dq/dt = v (see `SecondOrderFactor`).
    second_order: int = eqx.field(static=True, default=0)
    # The model prefers the sequential elimination (`block_factor`).
    sequential: bool = eqx.field(static=True, default=False)

    def _pad(self, x):
        N, B = self.diag.shape[0], self.diag.shape[1]
        flat = x.reshape(-1)
        return jnp.pad(flat, (0, N * B - flat.size)).reshape(N, B)

    def _unpad(self, X):
        return X.reshape(-1)[: self.n * self.b].reshape(self.n, self.b)

    def matvec(self, x):
        X = self._pad(x)
        z = jnp.zeros_like(X[:1])
        left = jnp.concatenate([z, X[:-1]], axis=0)
        right = jnp.concatenate([X[1:], z], axis=0)
        # Broadcast multiply-adds (`_mv`), which XLA:CPU fuses into one loop; batched
        # `dot`s of 2 x 2 blocks are separate kernels.
        out = _mv(self.lower, left) + _mv(self.diag, X) + _mv(self.upper, right)
        return self._unpad(out)

    def scale_shift(self, alpha, beta):
        """alpha I + beta self (padding rows stay identity)."""
        B = self.diag.shape[1]
        eye = jnp.eye(B, dtype=self.diag.dtype)
        pad_mask = self._pad_mask()
        diag = beta * self.diag + alpha * eye
        # keep padded unknowns decoupled with unit diagonal
        diag = jnp.where(pad_mask, eye, diag)
        return BlockTridiagonal(
            beta * self.lower,
            diag,
            beta * self.upper,
            self.n,
            self.b,
            self.width,
            self.second_order,
            self.sequential,
        )

    def _pad_mask(self):
        N, B = self.diag.shape[0], self.diag.shape[1]
        real = (jnp.arange(N * B) < self.n * self.b).reshape(N, B)
        # a block entry (i, j) is "padding" if row i or column j is a padded unknown
        return ~(real[:, :, None] & real[:, None, :])

    def to_dense(self):
        N, B = self.diag.shape[0], self.diag.shape[1]
        M = jnp.zeros((N * B, N * B), self.diag.dtype)
        for I in range(N):
            s = slice(I * B, (I + 1) * B)
            M = M.at[s, s].set(self.diag[I])
            if I > 0:
                M = M.at[s, (I - 1) * B : I * B].set(self.lower[I])
            if I < N - 1:
                M = M.at[s, (I + 1) * B : (I + 2) * B].set(self.upper[I])
        m = self.n * self.b
        return M[:m, :m]


def block_tridiagonal_jacobian(
    fn, y, width: int, linear_fn=None, second_order: int = 0, sequential=False
) -> BlockTridiagonal:
    """Jacobian of `fn` at `y` (node-major `(n, b)`) as a block-tridiagonal matrix of
    `width`-node super-blocks, from 3 B JVPs (B = width * b).

    `linear_fn`, if given, is the JVP `v -> J v` (e.g. from `jax.linearize`), so
    that a caller that already linearised does not do it again. `second_order`
    (d > 0, with `width` 1 and b = 2 d) marks the (q, v) node layout for `factor`;
    `sequential` the model's preference for the sequential elimination
    (`declared_sequential`).
    """
    n, b = y.shape
    if linear_fn is None:
        _, linear_fn = jax.linearize(fn, y)
    seeds = jnp.asarray(_band_seeds(n, b, width, 3), dtype=y.dtype)
    out = jax.vmap(linear_fn)(seeds)  # (3B, n, b)
    return _band_from_jvps(out, n, b, width, 3, second_order, sequential)


def _band_seeds(n, b, width, colours):
    """The coloured unit directions `(colours B, n, b)`: colour (r, c) is component
    c of every super-block I = r (mod colours); colours >= 3 keeps neighbouring
    super-blocks apart."""
    B = width * b
    N = math.ceil(n / width)
    blk = np.arange(N) % colours
    seeds = np.zeros((colours, B, N, B))
    for r in range(colours):
        for c in range(B):
            seeds[r, c, blk == r, c] = 1.0
    return seeds.reshape(colours * B, N * B)[:, : n * b].reshape(colours * B, n, b)


def _band_from_jvps(out, n, b, width, colours, second_order, sequential):
    """The `BlockTridiagonal` from the JVPs `out` `(colours B, n, b)` of the
    `_band_seeds`."""
    B = width * b
    N = math.ceil(n / width)
    out = out.reshape(colours * B, n * b)
    out = jnp.pad(out, ((0, 0), (0, N * B - n * b))).reshape(colours, B, N, B)
    # out[r, c, I, i] = sum over blocks J = r (mod colours), |I - J| <= 1 of
    # J[I i, J c].
    idx = np.arange(N)
    # (N, B_row, B_col) for each neighbour offset
    take = lambda r: jnp.transpose(out[r, :, idx, :], (0, 2, 1))  # (N, i, c)
    diag = take(idx % colours)
    lower = take((idx - 1) % colours)
    upper = take((idx + 1) % colours)
    first = np.zeros((N, 1, 1), bool)
    first[0] = True
    last = np.zeros((N, 1, 1), bool)
    last[-1] = True
    lower = jnp.where(first, 0.0, lower)
    upper = jnp.where(last, 0.0, upper)
    # Padded unknowns (n not a multiple of width) have no seeds and no outputs, so
    # their entries are already zero: give them a unit diagonal.
    real = np.arange(N * B) < n * b
    if not real.all():
        pad_eye = np.eye(B)[None] * (~real.reshape(N, B))[:, :, None]
        diag = diag + jnp.asarray(pad_eye, diag.dtype)
    d = second_order if (width == 1 and b == 2 * second_order) else 0
    return BlockTridiagonal(lower, diag, upper, n, b, width, d, bool(sequential))


# ----------------------------------------------------------------------------
# Block cyclic reduction
# ----------------------------------------------------------------------------


class _Level(eqx.Module):
    alpha: Array  # (me, B, B): L_even D_odd_left^{-1}
    beta: Array  # (me, B, B): U_even D_odd_right^{-1}
    dinv: Array  # (mo, B, B)
    lo: Array  # (mo, B, B)
    uo: Array  # (mo, B, B)


class BCRFactor(eqx.Module):
    levels: tuple
    dinv_last: Array  # (B, B)


# Batched small products as broadcast-multiply-sum: XLA:CPU fuses these into one
# loop, whereas a batched `dot` of 4 x 4 blocks is a separate, slower kernel.
def _mm(a, b):
    return jnp.sum(a[..., :, :, None] * b[..., None, :, :], axis=-2)


def _mv(a, x):
    return jnp.sum(a * x[..., None, :], axis=-1)


def _shift_right(x, length):
    """[0, x_0, x_1, ...] cut or zero-padded to `length` blocks."""
    z = jnp.zeros((1,) + x.shape[1:], x.dtype)
    y = jnp.concatenate([z, x], axis=0)
    return _fit(y, length)


def _fit(x, length):
    if x.shape[0] >= length:
        return x[:length]
    z = jnp.zeros((length - x.shape[0],) + x.shape[1:], x.dtype)
    return jnp.concatenate([x, z], axis=0)


def _det(m):
    """Determinant of a (small) matrix given as nested lists of arrays, by Laplace
    expansion along its first row."""
    if len(m) == 1:
        return m[0][0]
    if len(m) == 2:
        return m[0][0] * m[1][1] - m[0][1] * m[1][0]
    terms = [
        (-1) ** j * m[0][j] * _det([row[:j] + row[j + 1 :] for row in m[1:]])
        for j in range(len(m))
    ]
    return sum(terms[1:], terms[0])


def _adjugate_inverse(a):
    """Inverse of a batch of 2 x 2, 3 x 3 or 4 x 4 matrices as adjugate / determinant.

    No pivoting is needed: the cofactors are sums of products with one entry from
    each of the other rows and columns, so scaling a row or a column of `a` scales
    every term of a cofactor alike (no cancellation from badly scaled rows); the
    result is as accurate as a pivoted elimination for the well-conditioned blocks
    of chain Newton matrices (tests/solvers/test_linalg.py)."""
    B = a.shape[-1]
    e = [[a[..., i, j] for j in range(B)] for i in range(B)]

    def minor(i, j):
        return [row[:j] + row[j + 1 :] for k, row in enumerate(e) if k != i]

    cof = [[(-1) ** (i + j) * _det(minor(i, j)) for j in range(B)] for i in range(B)]
    det = sum((e[0][j] * cof[0][j] for j in range(1, B)), e[0][0] * cof[0][0])
    adj = jnp.stack(
        [jnp.stack([cof[j][i] for j in range(B)], -1) for i in range(B)], -2
    )
    return adj / det[..., None, None]


def small_inv(a):
    """Inverse of a batch of small matrices `(..., B, B)`: in closed form
    (`_adjugate_inverse`) up to 4 x 4, by `pivoted_inverse` up to 8 x 8 and by
    LAPACK above (timings: docs/numerics.md, "Banded linear algebra")."""
    B = a.shape[-1]
    if B == 1:
        return 1.0 / a
    if B <= 4:
        return _adjugate_inverse(a)
    if B > 8:
        return jnp.linalg.inv(a)
    return pivoted_inverse(a)


def pivoted_inverse(a):
    """Inverse of a batch of small matrices `(..., B, B)` by Gauss-Jordan elimination
    with partial pivoting (`pivoted_solve` with the identity on the right).

    XLA:CPU lowers ``jnp.linalg.inv`` to one LAPACK call per matrix of the batch;
    for the 5 x 5 ... 8 x 8 blocks of a string these elementwise ops (which XLA
    fuses) are faster. The columns are a `fori_loop`, not unrolled: block cyclic
    reduction inverts at each of its levels, and the unrolled eliminations made a
    quarter of a natural-variables solve's compilation, for the same run time
    (docs/numerics.md, "Banded linear algebra").
    """
    B = a.shape[-1]
    eye = jnp.broadcast_to(jnp.eye(B, dtype=a.dtype), a.shape)
    return pivoted_solve(a, eye)


def pivoted_solve(a, rhs):
    """`a^-1 rhs` for a batch of small matrices `a` `(..., B, B)` and right-hand
    sides `rhs` `(..., B, K)`: Gauss-Jordan elimination with partial pivoting, a
    loop over the B columns, with the batch as the last (contiguous) axis so that
    every operation is vectorised over the batch.

    No LAPACK call: XLA:CPU compiles a while loop whose body holds a custom call
    (LAPACK's getrf, getrs, trsm) as a sequence of kernels, never as one
    whole-loop function (performance.md, "Whole-loop kernels on the CPU"), so the
    small dense solves inside a step (a Schur complement, the rigid bodies' mass
    matrix) use this."""
    B, K = a.shape[-1], rhs.shape[-1]
    batch = a.shape[:-2]
    x = jnp.moveaxis(a.reshape((-1, B, B)), 0, -1)  # (B, B, m)
    r = jnp.moveaxis(rhs.reshape((-1, B, K)), 0, -1)  # (B, K, m)
    m = jnp.concatenate([x, r.astype(x.dtype)], axis=1)  # (B, B + K, m): [a | rhs]
    rows = jnp.arange(B)[:, None]

    def column(j, m):
        # Pivot: the largest |entry| of column j in rows j..B-1, swapped into row j.
        col = lax.dynamic_index_in_dim(m, j, axis=1, keepdims=False)  # (B, m)
        col = jnp.where(rows >= j, jnp.abs(col), -1.0)
        onehot = (rows == jnp.argmax(col, axis=0)[None, :]).astype(a.dtype)
        row_p = jnp.sum(onehot[:, None, :] * m, axis=0)  # (B + K, m)
        row_j = lax.dynamic_index_in_dim(m, j, axis=0, keepdims=False)
        m = m + onehot[:, None, :] * (row_j - row_p)[None]
        row_p = row_p / lax.dynamic_index_in_dim(row_p, j, axis=0)
        col = lax.dynamic_index_in_dim(m, j, axis=1, keepdims=False)
        factor_ = jnp.where(rows == j, 0.0, col)  # (B, m)
        m = m - factor_[:, None, :] * row_p[None]
        return jnp.where((rows == j)[:, :, None], row_p[None], m)

    m = lax.fori_loop(0, B, column, m)
    return jnp.moveaxis(m[:, B:, :], -1, 0).reshape(batch + (B, K))


def bcr_factor(mat: BlockTridiagonal) -> BCRFactor:
    """Block cyclic reduction of a block-tridiagonal matrix (no pivoting across
    blocks; the B x B blocks inverted by `small_inv`).

    One level eliminates the odd-numbered blocks: with `a = L_i D_{i-1}^{-1}` and
    `c = U_i D_{i+1}^{-1}`, even row i becomes
    `D_i - a U_{i-1} - c L_{i+1}` on the diagonal, `-a L_{i-1}` and `-c U_{i+1}`
    towards i - 2 and i + 2. Levels are unrolled at trace time (ceil(log2 N)).
    """
    L, D, U = mat.lower, mat.diag, mat.upper
    levels = []
    while D.shape[0] > 1:
        m = D.shape[0]
        me = (m + 1) // 2
        Le, De, Ue = L[0::2], D[0::2], U[0::2]
        Lo, Do, Uo = L[1::2], D[1::2], U[1::2]
        dinv = small_inv(Do)
        alpha = _mm(Le, _shift_right(dinv, me))
        beta = _mm(Ue, _fit(dinv, me))
        D = De - _mm(alpha, _shift_right(Uo, me)) - _mm(beta, _fit(Lo, me))
        L = -_mm(alpha, _shift_right(Lo, me))
        U = -_mm(beta, _fit(Uo, me))
        levels.append(_Level(alpha, beta, dinv, Lo, Uo))
    return BCRFactor(tuple(levels), small_inv(D[0]))


class ThomasFactor(eqx.Module):
    """Block LU of a block-tridiagonal matrix, sequential over the blocks
    (`thomas_factor`)."""

    w: Array  # (N - 1, B, B): L_i D'_{i-1}^{-1}, the forward sweep's multipliers
    dinv: Array  # (N, B, B): inverses of the eliminated diagonal blocks D'_i
    upper: Array  # (N, B, B): the matrix's upper blocks


def thomas_factor(mat: BlockTridiagonal) -> ThomasFactor:
    """Block Gaussian elimination from the first block to the last (the block Thomas
    algorithm): `D'_0 = D_0`, `D'_i = D_i - L_i D'_{i-1}^{-1} U_{i-1}`, in one
    `lax.scan` (no pivoting across blocks, as block cyclic reduction; `small_inv`
    inverses of the B x B blocks). The compiled program holds one
    elimination step whatever the number of blocks."""
    L, D, U = mat.lower, mat.diag, mat.upper
    dinv0 = small_inv(D[0])

    def eliminate(dinv_prev, blocks):
        lower, diag, upper_prev = blocks
        w = _mm(lower, dinv_prev)
        dinv = small_inv(diag - _mm(w, upper_prev))
        return dinv, (w, dinv)

    _, (w, dinv) = lax.scan(eliminate, dinv0, (L[1:], D[1:], U[:-1]))
    return ThomasFactor(w, jnp.concatenate([dinv0[None], dinv], axis=0), U)


def thomas_solve(fac: ThomasFactor, f):
    """Solve with a `thomas_factor` factorisation; `f` has shape (N, B)."""

    def forward(z_prev, rows):
        w, fi = rows
        z = fi - _mv(w, z_prev)
        return z, z

    _, z = lax.scan(forward, f[0], (fac.w, f[1:]))
    z = jnp.concatenate([f[:1], z], axis=0)
    x_last = _mv(fac.dinv[-1], z[-1])

    def backward(x_next, rows):
        dinv, zi, upper = rows
        x = _mv(dinv, zi - _mv(upper, x_next))
        return x, x

    rows = (fac.dinv[:-1], z[:-1], fac.upper[:-1])
    _, x = lax.scan(backward, x_last, rows, reverse=True)
    return jnp.concatenate([x, x_last[None]], axis=0)


SEQUENTIAL_MAX_BLOCK = 2
"""`block_factor` eliminates block-tridiagonal matrices of blocks up to this size
sequentially (`thomas_factor`), larger ones by block cyclic reduction."""


def block_factor(mat: BlockTridiagonal):
    """The factorisation of a block-tridiagonal matrix for `block_solve`: the block
    Thomas algorithm for blocks of at most `SEQUENTIAL_MAX_BLOCK` rows on the CPU
    (its closed-form 2 x 2 inverses make each sequential step a few fused
    operations: as fast to run as the reduction for the strings measured, and its
    program, one step in a loop, compiles several times faster than the reduction's
    unrolled levels), and for blocks of any size of a model that prefers it
    (`SolverStructure.sequential_elimination`: mooring lines, with or without
    bodies and rods, whose whole solves compile and run faster so); block cyclic
    reduction otherwise (O(log N) depth, for larger blocks and for
    accelerators)."""
    small = mat.diag.shape[-1] <= SEQUENTIAL_MAX_BLOCK
    if (small or mat.sequential) and jax.default_backend() == "cpu":
        return thomas_factor(mat)
    return bcr_factor(mat)


@jax.jit
def block_solve(fac, f):
    """Solve with a `block_factor` factorisation; `f` has shape (N, B)."""
    if isinstance(fac, ThomasFactor):
        return thomas_solve(fac, f)
    return bcr_solve(fac, f)


# `bcr_solve` and `factor` are jitted functions called inside the solvers' traces:
# diffrax traces a solver's step three times, and a nested jit traces each of these
# once per shape (a cache hit after that); XLA inlines them, so the compiled program
# is the same and tracing is shorter (measured: docs/numerics.md, "BLAS and XLA
# notes").
@jax.jit
def bcr_solve(fac: BCRFactor, f):
    """Solve with a `bcr_factor` factorisation; `f` has shape (N, B)."""
    stack = []
    for lev in fac.levels:
        fe, fo = f[0::2], f[1::2]
        me = fe.shape[0]
        stack.append(fo)
        f = fe - _mv(lev.alpha, _shift_right(fo, me)) - _mv(lev.beta, _fit(fo, me))
    x = (fac.dinv_last @ f[0])[None]
    for lev, fo in zip(reversed(fac.levels), reversed(stack)):
        mo = fo.shape[0]
        me = x.shape[0]
        xo = _mv(lev.dinv, fo - _mv(lev.lo, x[:mo]) - _mv(lev.uo, _fit(x[1:], mo)))
        if me == mo:
            x = jnp.stack([x, xo], axis=1).reshape(2 * mo, -1)
        else:
            inter = jnp.stack([x[:-1], xo], axis=1).reshape(2 * mo, -1)
            x = jnp.concatenate([inter, x[-1:]], axis=0)
    return x


# ----------------------------------------------------------------------------
# One interface over the dense and banded paths
# ----------------------------------------------------------------------------


class DenseJacobian(eqx.Module):
    """A dense Jacobian of a pytree -> same-pytree map (flattened)."""

    matrix: Array

    def scale_shift(self, alpha, beta):
        eye = jnp.eye(self.matrix.shape[0], dtype=self.matrix.dtype)
        return DenseJacobian(alpha * eye + beta * self.matrix)


class DenseFactor(eqx.Module):
    lu: Array
    piv: Array

    def solve(self, rhs):
        flat, unravel = jfu.ravel_pytree(rhs)
        return unravel(jsl.lu_solve((self.lu, self.piv), flat))


class BandedFactor(eqx.Module):
    fac: Any  # BCRFactor or ThomasFactor (`block_factor`)
    n: int = eqx.field(static=True)
    b: int = eqx.field(static=True)
    N: int = eqx.field(static=True)
    B: int = eqx.field(static=True)

    def solve(self, rhs):
        flat = rhs.reshape(-1)
        X = jnp.pad(flat, (0, self.N * self.B - flat.size)).reshape(self.N, self.B)
        x = block_solve(self.fac, X)
        return x.reshape(-1)[: self.n * self.b].reshape(self.n, self.b)


class SecondOrderFactor(eqx.Module):
    """Factorisation of a block-tridiagonal Newton matrix `a I + b J` of a vector
    field whose node rows are (q, v) with dq/dt = v exactly (d components each).

    Its q rows are `a p_i + b q_i = r_i` (no coupling between nodes), so
    `p = (r - b q) / a` and the v rows become, on the velocities alone,
    `(Q - P diag(b / a)) q = s - P (r / a)` with P, Q the v rows' q and v columns:
    block-tridiagonal with d x d blocks, factorised by block cyclic reduction. This
    is the classical reduction of the Newton system of a second-order ODE (Hairer
    & Wanner, IV.8); for a 2D string it halves the block size, so the reduction's
    block products cost 8x fewer flops and the block inverses are closed-form.

    The q rows' structure is checked on the values: if they are not
    `[a I, b I]` with no neighbour coupling (a model that declared `second_order`
    wrongly, or a relation that is not `a I + b J`), the factor is NaN, so the
    Newton iteration fails loudly instead of converging to a wrong root.
    """

    sfac: Any  # BCRFactor or ThomasFactor (`block_factor`)
    p: BlockTridiagonal  # the v rows' q columns, d x d blocks
    inv_alpha: Array  # (n,): 1 / a
    ratio: Array  # (n,): b / a

    def solve(self, rhs):
        d = self.p.b
        r, s = rhs[:, :d], rhs[:, d:]
        rq = s - self.p.matvec(r * self.inv_alpha[:, None])
        q = block_solve(self.sfac, rq)
        p = r * self.inv_alpha[:, None] - self.ratio[:, None] * q
        return jnp.concatenate([p, q], axis=1)


def second_order_factor(mat: BlockTridiagonal) -> SecondOrderFactor:
    """`SecondOrderFactor` of a `BlockTridiagonal` with `second_order` = d > 0."""
    d, n = mat.second_order, mat.n
    qd = mat.diag[:, :d, :]  # the q rows of the diagonal blocks, (n, d, 2d)
    alpha, beta = qd[:, 0, 0], qd[:, 0, d]
    eye = jnp.eye(d, dtype=mat.diag.dtype)
    expect = jnp.concatenate(
        [alpha[:, None, None] * eye, beta[:, None, None] * eye], axis=-1
    )
    off = jnp.max(jnp.abs(mat.lower[:, :d, :])) + jnp.max(jnp.abs(mat.upper[:, :d, :]))
    ok = (off == 0) & jnp.all(qd == expect) & jnp.all(alpha != 0)
    inv_alpha = jnp.where(ok, 1.0 / jnp.where(alpha != 0, alpha, 1.0), jnp.nan)
    ratio = beta * inv_alpha
    v_rows = lambda m, lo, hi: m[:, d:, lo:hi]
    P = [v_rows(m, 0, d) for m in (mat.lower, mat.diag, mat.upper)]
    Q = [v_rows(m, d, 2 * d) for m in (mat.lower, mat.diag, mat.upper)]
    # S_ij = Q_ij - P_ij (b / a)_j: column scaling by the ratio of node j.
    zero = jnp.zeros_like(ratio[:1])
    r_prev = jnp.concatenate([zero, ratio[:-1]])
    r_next = jnp.concatenate([ratio[1:], zero])
    S = BlockTridiagonal(
        Q[0] - P[0] * r_prev[:, None, None],
        Q[1] - P[1] * ratio[:, None, None],
        Q[2] - P[2] * r_next[:, None, None],
        n,
        d,
        1,
        sequential=mat.sequential,
    )
    return SecondOrderFactor(
        block_factor(S), BlockTridiagonal(*P, n, d, 1), inv_alpha, ratio
    )


class SecondOrderJacobian(eqx.Module):
    """`a I + b J` for the Jacobian J = [[0, I], [P, Q]] of a vector field whose node
    rows are (q, v) with dq/dt = v (d components each), stored as its v rows only:
    P (d/dq) and Q (d/dv), block-tridiagonal with d x d blocks.

    A model that knows this structure builds it directly
    (`AbstractModel.vf_jacobian`), so neither the q rows nor the 2 d x 2 d blocks
    are formed, and `factor` goes straight to the reduced system of
    `SecondOrderFactor` without checking the q rows on the values.
    """

    p: BlockTridiagonal
    q: BlockTridiagonal
    a: Array
    b: Array

    def scale_shift(self, alpha, beta):
        """alpha I + beta (a I + b J)."""
        return SecondOrderJacobian(self.p, self.q, alpha + beta * self.a, beta * self.b)

    def matvec(self, x):
        d = self.p.b
        xq, xv = x[:, :d], x[:, d:]
        top = self.a * xq + self.b * xv
        bottom = self.a * xv + self.b * (self.p.matvec(xq) + self.q.matvec(xv))
        return jnp.concatenate([top, bottom], axis=1)

    def to_dense(self):
        n, d = self.p.n, self.p.b
        P, Q = self.p.to_dense(), self.q.to_dense()
        eye = jnp.eye(n * d, dtype=P.dtype)
        M = jnp.block([[jnp.zeros_like(P), eye], [P, Q]])
        M = self.a * jnp.eye(2 * n * d, dtype=P.dtype) + self.b * M
        # (q block, v block) order -> node-major (q_i, v_i) rows and columns
        perm = np.arange(2 * n * d).reshape(2, n, d).transpose(1, 0, 2).reshape(-1)
        return M[perm][:, perm]


def _second_order_jacobian_factor(mat: SecondOrderJacobian) -> "SecondOrderFactor":
    """The reduced factorisation of `a I + b [[0, I], [P, Q]]`: the v rows become
    (a I + b Q - (b^2 / a) P) v = s - (b / a) P r (see `SecondOrderFactor`)."""
    n, d = mat.p.n, mat.p.b
    a, b = mat.a, mat.b
    ratio = b / a
    eye = jnp.eye(d, dtype=mat.p.diag.dtype)
    S = BlockTridiagonal(
        b * mat.q.lower - (b * ratio) * mat.p.lower,
        a * eye + b * mat.q.diag - (b * ratio) * mat.p.diag,
        b * mat.q.upper - (b * ratio) * mat.p.upper,
        n,
        d,
        1,
    )
    P = BlockTridiagonal(b * mat.p.lower, b * mat.p.diag, b * mat.p.upper, n, d, 1)
    full = lambda x: jnp.broadcast_to(x, (n,))
    return SecondOrderFactor(block_factor(S), P, full(1.0 / a), full(ratio))


def declared_second_order(fn, y, args=None) -> int:
    """d > 0 when the scene's model (found as in `declared_width`) declares the
    (q, v) node layout with dq/dt = v (`SolverStructure.second_order`) and `y` has
    the scene's state shape; else 0."""
    scene = _declared_scene(fn, y, args)
    return 0 if scene is None else int(scene.structure.second_order)


def declared_sequential(fn, y, args=None) -> bool:
    """Whether the scene's model prefers the sequential elimination of its Newton
    blocks (`SolverStructure.sequential_elimination`), where `y` has the scene's
    state shape."""
    scene = _declared_scene(fn, y, args)
    return scene is not None and bool(scene.structure.sequential_elimination)


def model_jacobian(terms, t, y, args):
    """The model's own Jacobian (`AbstractModel.vf_jacobian`, where its
    `SolverStructure.jacobian` says it has one) when the ODE is a scene's vector
    field (as `simulate` builds it), else None."""
    # diffrax's internal WrapTerm (for the direction of time): vf(t) = term.vf(d t)
    while hasattr(terms, "term") and hasattr(terms, "direction"):
        t, terms = t * terms.direction, terms.term
    if not (
        isinstance(terms, dfx.ODETerm)
        and terms.vector_field is scene_vector_field
        and isinstance(args, Scene)
        and tuple(y.shape) == tuple(args.y0.shape)
        and args.structure.jacobian
    ):
        return None
    return args.model.vf_jacobian(t, y, args.effects, args.env)


def jacobian(fn, y, width, linear_fn=None, second_order=0, sequential=False):
    """Jacobian of `fn` at `y`: `BlockTridiagonal` if `width` is an int, else dense.
    `second_order` > 0 (from `declared_second_order`) selects the reduced
    factorisation of `SecondOrderFactor` for the matrices built from it;
    `sequential` (from `declared_sequential`) the sequential elimination."""
    if width is None:
        flat, unravel = jfu.ravel_pytree(y)
        f_flat = lambda v: jfu.ravel_pytree(fn(unravel(v)))[0]
        return DenseJacobian(jax.jacfwd(f_flat)(flat))
    if isinstance(width, BorderedWidth):
        return bordered_jacobian(fn, y, width, linear_fn, second_order, sequential)
    return block_tridiagonal_jacobian(fn, y, width, linear_fn, second_order, sequential)


@jax.jit
def factor(mat):
    """Factorise a `DenseJacobian`-like, `BlockTridiagonal`, `SecondOrderJacobian`
    or `BorderedJacobian` matrix."""
    return _factor(mat)


def _factor(mat):
    if isinstance(mat, BorderedJacobian):
        return _bordered_factor(mat)
    if isinstance(mat, SecondOrderJacobian):
        return _second_order_jacobian_factor(mat)
    if isinstance(mat, BlockTridiagonal):
        if mat.second_order:
            return second_order_factor(mat)
        N, B = mat.diag.shape[0], mat.diag.shape[1]
        return BandedFactor(block_factor(mat), mat.n, mat.b, N, B)
    lu, piv = jsl.lu_factor(mat.matrix)
    return DenseFactor(lu, piv)


# ----------------------------------------------------------------------------
# A band with a border: a few rows and columns coupled to everything
# ----------------------------------------------------------------------------


class BorderedJacobian(eqx.Module):
    """`[[A, R], [C, D]]` for a node-major `(n, b)` state whose first `k` rows
    (the border) couple to every row: `A` `(k b, k b)`, `R` `(k b, m)`, `C`
    `(m, k b)` and the band `D`, a `BlockTridiagonal` of the other `n - k` rows
    (m = (n - k) b)."""

    A: Array
    R: Array
    C: Array
    band: BlockTridiagonal
    k: int = eqx.field(static=True)

    def scale_shift(self, alpha, beta):
        """alpha I + beta self."""
        eye = jnp.eye(self.A.shape[0], dtype=self.A.dtype)
        return BorderedJacobian(
            alpha * eye + beta * self.A,
            beta * self.R,
            beta * self.C,
            self.band.scale_shift(alpha, beta),
            self.k,
        )

    def to_dense(self):
        return jnp.block([[self.A, self.R], [self.C, self.band.to_dense()]])


def bordered_jacobian(
    fn, y, spec: BorderedWidth, linear_fn=None, second_order=0, sequential=False
):
    """The Jacobian of `fn` at `y` (node-major `(n, b)`) as a `BorderedJacobian`:
    the band of the rows after the border from coloured JVPs
    (`block_tridiagonal_jacobian` with the border held), the border's columns from
    `k b` JVPs, and its rows either from the band's JVPs or from `k b` transposed
    JVPs.

    The band's JVPs give the border's rows where the model names the rows the
    border depends on (`spec.coupled`, `SolverStructure.border_coupled`) and the
    colouring keeps their super-blocks in different colours (super-blocks
    I = r mod c share a JVP; c >= 3 the smallest that does, (c - 3) B JVPs more
    than the band alone). That is used where it costs fewer JVPs than the
    transposes, each about one and a half JVPs."""
    k = spec.border
    n, b = y.shape
    m = n - k
    if linear_fn is None:
        _, linear_fn = jax.linearize(fn, y)
    kb = k * b
    B = spec.width * b
    N = math.ceil(m / spec.width)
    blocks = sorted({r // spec.width for r in spec.coupled})
    colours = _border_colours(spec, n)
    # the border's columns: unit directions in its rows (those of `spec.columns`,
    # the entries the vector field reads and changes)
    live = np.asarray(spec.columns or range(kb), np.int32)
    border_seeds = np.zeros((live.size, n, b))
    border_seeds[:, :k] = np.eye(kb)[live].reshape(live.size, k, b)
    # The other entries' columns are zero in the vector field's Jacobian, but not
    # in that of a relation built on it (an implicit stage's u - a h f(y_i + a h u),
    # a tangent solve's (c J - I) v, a fixed step's residual): there they are the
    # relation's identity part, diagonal. One JVP along their sum gives those
    # diagonal entries (zeros for the vector field itself).
    dead = np.setdiff1d(np.arange(kb), live)
    dead_seed = np.zeros((int(dead.size > 0), n, b))
    dead_seed.reshape(-1, n * b)[:, dead] = 1.0
    on_dead = np.zeros((kb, n * b))
    on_dead[dead, dead] = 1.0
    column_seeds = np.concatenate([border_seeds, dead_seed])

    def unit_columns(out):  # J e_c for every live c of the border, (kb, n b)
        out = out.reshape(live.size, n * b)
        if live.size == kb:
            return out
        return add_rows(kb, live, out)

    def border_columns(out):  # J e_c for every c of the border, (kb, n b)
        out = out.reshape(column_seeds.shape[0], n * b)
        cols = unit_columns(out[: live.size])
        if dead.size:
            cols = cols + jnp.asarray(on_dead, out.dtype) * out[live.size :]
        return cols

    if colours is None:
        band = block_tridiagonal_jacobian(
            None,
            y[k:],
            spec.width,
            lambda v: linear_fn(jnp.concatenate([jnp.zeros((k, b), y.dtype), v]))[k:],
            second_order,
            sequential,
        )
        cols = border_columns(jax.vmap(linear_fn)(jnp.asarray(column_seeds, y.dtype)))
        transpose = jax.linear_transpose(linear_fn, y)
        rows = jax.vmap(lambda s: transpose(s)[0])(jnp.asarray(border_seeds, y.dtype))
        rows = unit_columns(rows)[:, kb:]
        return BorderedJacobian(cols[:, :kb].T, rows, cols[:, kb:].T, band, k)
    # the band's coloured directions and the border's columns in one batch
    band_seeds = np.zeros((colours * B, n, b))
    band_seeds[:, k:] = _band_seeds(m, b, spec.width, colours)
    seeds = jnp.asarray(np.concatenate([band_seeds, column_seeds]), y.dtype)
    out = jax.vmap(linear_fn)(seeds)
    nb = colours * B
    band = _band_from_jvps(
        out[:nb, k:], m, b, spec.width, colours, second_order, sequential
    )
    cols = border_columns(out[nb:])  # cols[c] = J e_c
    # out[r B + c, :k]: the border's rows of J e_c over the super-blocks of
    # colour r, that is of the one coupled super-block there (the others add
    # zeros)
    head = out[:nb, :k].reshape(colours, B, kb)
    idx = np.asarray(blocks, np.int32)
    R = add_rows(N, idx, jnp.transpose(head[idx % colours], (0, 2, 1)))
    rows = jnp.transpose(R, (1, 0, 2)).reshape(kb, N * B)[:, : m * b]
    return BorderedJacobian(cols[:, :kb].T, rows, cols[:, kb:].T, band, k)


def _border_colours(spec: BorderedWidth, n):
    """The band's colour count of `bordered_jacobian` for a state of `n` nodes:
    c >= 3 keeping the coupled super-blocks apart (`_colours_apart`), or None where
    the transposed JVPs cost less (or no coupled rows are named)."""
    N = math.ceil((n - spec.border) / spec.width)
    colours = _colours_apart(sorted({r // spec.width for r in spec.coupled}), N)
    # (c - 3) B more JVPs than the band's, against 1.5 k b transposed ones more
    if colours is not None and 2 * (colours - 3) * spec.width > 3 * spec.border:
        return None
    return colours


def jacobian_directions(width, shape) -> int:
    """The JVPs `jacobian` takes at a state of `shape` (node-major `(n, b)`) for
    `width` as `choose_structure` gives it: its cost in vector fields (a transposed
    JVP counted as one and a half)."""
    if width is None:
        return math.prod(shape)
    n, b = shape
    if not isinstance(width, BorderedWidth):
        return 3 * width * b
    live = len(width.columns) or width.border * b
    dead = int(live < width.border * b)  # one JVP for the unread entries
    colours = _border_colours(width, n)
    if colours is None:
        return 3 * width.width * b + live + dead + math.ceil(1.5 * live)
    return colours * width.width * b + live + dead


def _colours_apart(blocks, N):
    """The smallest colour count c >= 3 with the super-blocks `blocks` in
    different colours (I mod c), or None (no coupled rows named)."""
    if not blocks:
        return None
    for c in range(3, max(N, 3) + 1):
        if len({J % c for J in blocks}) == len(blocks):
            return c
    return None


class BorderedFactor(eqx.Module):
    """The factorisation of a `BorderedJacobian`: the band's factor, `X = D^-1 C`
    and the inverse of the Schur complement `A - R X` (`pivoted_inverse`: a
    `k b` x `k b` matrix of a few rigid objects' rows, and no LAPACK call in the
    step's loop)."""

    band: eqx.Module
    X: Array
    R: Array
    schur_inv: Array
    k: int = eqx.field(static=True)

    def solve(self, rhs):
        k = self.k
        b = rhs.shape[1]
        rb, rl = rhs[:k].reshape(-1), rhs[k:]
        z = self.band.solve(rl).reshape(-1)
        xb = self.schur_inv @ (rb - self.R @ z)
        xl = z - self.X @ xb
        return jnp.concatenate([xb.reshape(k, b), xl.reshape(-1, b)])


def _bordered_factor(mat: BorderedJacobian) -> BorderedFactor:
    band = _factor(mat.band)
    m, b = mat.C.shape[0], mat.band.b
    X = jax.vmap(lambda c: band.solve(c.reshape(m // b, b)).reshape(-1), 1, 1)(mat.C)
    schur_inv = pivoted_inverse((mat.A - mat.R @ X)[None])[0]
    return BorderedFactor(band, X, mat.R, schur_inv, mat.k)
