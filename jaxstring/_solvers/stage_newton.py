"""Newton/chord iteration for the implicit stages of diffrax solvers.

Why not diffrax's default: diffrax 0.7.2's ``VeryChord`` (and ``optimistix.Chord``
with ``cauchy_termination=False``) end the iteration after two steps and report
divergence whenever the contraction estimate has not *already* met the tolerance --
even when the iteration is contracting nicely. Every harder stage solve then fails and
the step is rejected; stiff strings see thousands of needless rejections (fixed
upstream in diffrax PR 754 / optimistix PR 230, not released).

This root finder follows Hairer & Wanner, *Solving ODEs II*, section IV.8:

* the iteration continues while it contracts (rate ``theta < 1``);
* it has converged when ``theta / (1 - theta) * |dz| <= kappa`` (or the first
  increment is already negligible);
* it is declared divergent when ``theta >= 1``, or when the predicted error after the
  remaining iterations, ``theta**(k_max - k) / (1 - theta) * |dz|``, is still above
  ``kappa`` -- then the step is rejected early and retried with a smaller step.

Increments are measured in the units of the *state* y, scaled by ``atol + rtol |y|``
(the error-controller's norm). diffrax solves Kvaerno stages in "f-space" (the unknown
is the stage derivative f_i with y_i = y_partial + a_ii dt f_i) and implicit Euler in
"k-space" (the unknown is the increment); we recognise both argument layouts and
convert the increment to its effect on y, so the test does not depend on dt.

With ``newton=True`` the Jacobian is recomputed at every iteration (full Newton):
the right choice for fixed-step methods, which cannot reject a step.

Jacobian refresh (``refresh=True``, the default): when the iteration contracts
slowly (rate > ``refresh_rate``), diverges, or contracts too slowly to converge
within ``max_iters`` (Hairer's prediction), the Jacobian is recomputed at the
current iterate, up to ``max_jacobians`` times per solve (default 10), before
divergence is declared -- as production stiff codes refresh on convergence failure.
This is what makes the displacement string at EA >= 1e5 cheap: its stiff force
N = EA (|D r| - 1) t is strongly nonlinear in the state (the stiff axis turns with
the string, and the transverse "geometric" stiffness N / h is proportional to a strain
that the stage predictor gets wrong by an EA-magnified amount), so a Jacobian taken at
the predictor contracts at a rate near 1 for any step that is not tiny, and without
a refresh the step size is limited by Newton, never by accuracy (measured:
docs/numerics.md, "The stage Newton iteration" and "Jacobian refresh in the stage
Newton iteration"). (In natural variables the stiff force N = EA eps is linear in
the state, which is why they never had the problem.)

Linear algebra (``linear_solver``): ``"auto"`` uses a block-tridiagonal Jacobian from
a few coloured JVPs and block cyclic reduction (``jaxstring._linalg``) when the
state is node-major with a narrow band and large enough, and a dense ``jacfwd`` +
LU otherwise; ``"dense"`` and ``"banded"`` force one path.
"""

import functools
import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import jax.tree_util as jtu
import optimistix as optx
from jaxtyping import PyTree, Scalar

from .. import _linalg
from .._scene import Scene
from .diffrax_compat import stage_arguments
from .newton import contraction_test


class _NoAux(eqx.Module):
    fn: Callable

    def __call__(self, y, args):
        out, _ = self.fn(y, args)
        return out


class _StageState(eqx.Module):
    linear_state: PyTree[Any]
    diffsize: Scalar
    diffsize_prev: Scalar
    result: optx.RESULTS
    step: Scalar
    n_jac: Scalar
    refresh_next: Any
    y_init: PyTree[Any]  # this solve's starting guess (see `postprocess`)


def _to_y_units(diff, y_new, args):
    """Return (increment of the state, the new state) for diffrax's argument layouts."""
    a = stage_arguments(args)
    if a.kind == "esdirk_f":
        dy = jtu.tree_map(lambda d: a.diagonal * d, a.prod(diff, a.control))
        yi = jtu.tree_map(
            lambda p, f: p + a.diagonal * f, a.yi_partial, a.prod(y_new, a.control)
        )
        return dy, yi
    if a.kind == "esdirk_k":
        dy = jtu.tree_map(lambda d: a.diagonal * d, diff)
        yi = jtu.tree_map(lambda p, k: p + a.diagonal * k, a.yi_partial, y_new)
        return dy, yi
    if a.kind == "implicit_euler_k":
        return diff, jtu.tree_map(lambda p, k: p + k, a.y0, y_new)
    # Unknown layout: measure in the unknown's own units.
    return diff, y_new


def _explicit_stage(args) -> bool:
    """Whether `args` are diffrax's ESDIRK stage arguments with a diagonal that is
    the constant 0 (an explicit stage)."""
    a = stage_arguments(args)
    if a.kind not in ("esdirk_f", "esdirk_k"):
        return False
    diagonal = a.diagonal
    if isinstance(diagonal, jax.core.Tracer) or not hasattr(diagonal, "shape"):
        return False
    return diagonal.shape == () and bool(diagonal == 0)


def _stage_model_jacobian(u, args, shape_only=False):
    """The Jacobian of diffrax's implicit Runge-Kutta stage relation at `u` from the
    model's own Jacobian (`AbstractModel.vf_jacobian`), else None.

    diffrax's f-space relation (its ESDIRKs: Kvaerno) is
    `g(f) = f - vf(t_i, y_i + a prod(f, dt), args)`; for an ODE term, prod(f, dt) =
    f dt, so its Jacobian is `I - a dt J(t_i, y_i + a f dt)`. diffrax passes `vf`
    and `prod` closure-converted, so which term they belong to cannot be seen:
    the model's Jacobian is taken when the ODE's `args` are a `Scene`, and at run
    time `vf` must equal the scene's vector field and `prod` the product f dt
    (one vector field more per Jacobian), or the matrix is NaN and the Newton
    iteration fails loudly, as `SecondOrderFactor` does for a wrong structure.
    Any other relation, or a model without its own Jacobian, gives None: the
    Jacobian is probed with JVPs as before. `shape_only` (for the structure of
    its factorisation only): without the run-time check."""
    a = stage_arguments(args)
    if a.kind != "esdirk_f":
        return None
    diagonal, vf, prod, ti, yi, inner, control = (
        a.diagonal, a.vf, a.prod, a.ti, a.yi_partial, a.args, a.control
    )  # fmt: skip
    if not (isinstance(inner, Scene) and inner.structure.jacobian):
        return None
    if not (jnp.shape(control) == () and jnp.shape(yi) == jnp.shape(u)):
        return None
    step = prod(u, control)
    y_at = yi + diagonal * step

    def same():
        own = jnp.array_equal(vf(ti, y_at, inner), inner.vector_field(ti, y_at))
        return own & jnp.array_equal(step, u * control)

    return shifted_model_jacobian(
        inner, ti, y_at, -diagonal * control, None if shape_only else same
    )


def shifted_model_jacobian(scene, t, y, coefficient, same=None):
    """`I + coefficient J(t, y)` from the scene's model's own Jacobian
    (`AbstractModel.vf_jacobian`), or None where the model has none. `same()`:
    whether the relation being solved is the scene's own (its vector field);
    where it is not, the matrix is NaN, so that a Newton iteration fails loudly
    instead of using a wrong Jacobian (None: not checked, for a structure only)."""
    jac = scene.model.vf_jacobian(t, y, scene.effects, scene.env)
    if jac is None:
        return None
    if same is not None:
        coefficient = jnp.where(same(), coefficient, jnp.nan)
    return jac.scale_shift(1.0, coefficient)


def _identity_like(struct):
    """The factorisation of the identity with the structure `struct` (from
    `eqx.filter_eval_shape` of a factorisation): LU factors and the inverse diagonal
    blocks of the block eliminations are identity matrices (and 1 / a of a
    `SecondOrderFactor` is 1), pivots are 0, 1, ...,
    and every other array (the reduction's off-diagonal blocks) is zero."""

    def fill(path, leaf):
        if not isinstance(leaf, jax.ShapeDtypeStruct):
            return leaf
        name = getattr(path[-1], "name", "") if path else ""
        if name == "inv_alpha":
            return jnp.ones(leaf.shape, leaf.dtype)
        if name in ("lu", "dinv", "dinv_last"):
            eye = jnp.eye(leaf.shape[-1], dtype=leaf.dtype)
            return jnp.broadcast_to(eye, leaf.shape)
        if name == "piv":
            return jnp.broadcast_to(
                jnp.arange(leaf.shape[-1], dtype=leaf.dtype), leaf.shape
            )
        return jnp.zeros(leaf.shape, leaf.dtype)

    return jtu.tree_map_with_path(fill, struct)


def _rms(tree):
    leaves = jtu.tree_leaves(tree)
    sq = sum(jnp.sum(jnp.abs(x) ** 2) for x in leaves)
    n = sum(x.size for x in leaves)
    return jnp.sqrt(sq / n)


class StageNewton(optx.AbstractRootFinder):
    """Simplified (chord) or full Newton iteration with Hairer's convergence test.

    **Arguments:**

    - `rtol`, `atol`: tolerances of the iteration, in the units of the state.
    - `kappa`: safety factor: converged when the estimated remaining error is below
      `kappa` times the tolerance (Hairer & Wanner use 0.01 ... 0.1).
    - `max_iters`: the iteration limit the divergence prediction assumes; set the
      solver's `root_find_max_steps` to the same number.
    - `newton`: recompute the Jacobian at every iteration (for fixed-step methods).
    - `linear_solver`: `"auto"` (default), `"dense"` or `"banded"` (see the module
      docstring); or, for a state that stacks independent members along its leading
      axis (`jaxstring.sweep(..., mode="lockstep")`), `"batched"`,
      `"batched_dense"` or `"batched_banded"`: the Jacobian is block-diagonal
      over the members and is built and factorised per member (see
      `batched_factor`).
    - `refresh`: recompute the Jacobian at the current iterate when the iteration
      contracts slower than `refresh_rate` (or, with `refresh_when_hopeless`, too
      slowly to converge within `max_iters`), at most `max_jacobians` Jacobians per
      solve (the initial one included).
    - `first_jacobian_in_step`: `init` leaves the Jacobian to the first iteration's
      refresh (at the same point), so that a solver that calls `init` for every
      stage compiles the Jacobian once, not twice (with `refresh`, not `newton`;
      not for a state handed from one stage's solve to the next).
    """

    rtol: Any
    atol: Any
    norm: Callable = _rms
    kappa: float = 0.05
    max_iters: int = 10
    newton: bool = eqx.field(static=True, default=False)
    linear_solver: str = eqx.field(static=True, default="auto")
    refresh: bool = eqx.field(static=True, default=True)
    refresh_rate: float = 0.5
    max_jacobians: int = 10
    refresh_when_hopeless: bool = eqx.field(static=True, default=True)
    first_jacobian_in_step: bool = eqx.field(static=True, default=False)

    def _test(self, size, prev, it):
        """Hairer & Wanner's test (`newton.contraction_test`) after update `it`
        (0-based): (converged, too slow, rate)."""
        return contraction_test(
            size, prev, it, self.kappa, self.max_iters, 1e-3 * self.kappa, 1e-10
        )

    def _factor(self, fn, y, args, shape_only=False):
        """The factorised Jacobian of `fn(., args)` at `y`. With `shape_only` (for
        `eqx.filter_eval_shape`: the factorisation's structure only) the probed
        Jacobian is the identity's, whose structure is the same, so that taking
        the structure does not trace the relation's JVPs."""
        noaux = _NoAux(fn)
        if self.linear_solver in BATCHED_LINEAR_SOLVERS:
            fac = batched_factor(noaux, y, args, self.linear_solver, shape_only)
            return lax.stop_gradient(fac)
        width = _linalg.choose_structure(noaux, y, args, self.linear_solver)
        jac = _stage_model_jacobian(y, args, shape_only) if width == 1 else None
        if jac is None:
            so = _linalg.declared_second_order(noaux, y, args)
            seq = _linalg.declared_sequential(noaux, y, args)
            relation = (lambda u: u) if shape_only else (lambda u: noaux(u, args))
            jac = _linalg.jacobian(relation, y, width, second_order=so, sequential=seq)
        fac = _linalg.factor(jac)
        return lax.stop_gradient(fac)

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        del f_struct, aux_struct, tags
        init_state = options.get("init_state")
        if init_state is not None:
            return init_state
        leaves = jtu.tree_leaves(y)
        dtype = jnp.result_type(*leaves) if leaves else jnp.float64
        explicit = _explicit_stage(args)
        later = self.first_jacobian_in_step and self.refresh and not self.newton
        if explicit or later:
            # diffrax's ESDIRKs ask, once per step, for the "Jacobian" of their
            # explicit first stage (diagonal 0: the relation's Jacobian is I). It is
            # never used to solve, so build the identity factor, not a Jacobian.
            # With `first_jacobian_in_step` the first iteration's refresh takes
            # the Jacobian at the same point, so that the compiled solve holds one
            # copy of the Jacobian's program instead of two.
            shape = eqx.filter_eval_shape(
                functools.partial(self._factor, shape_only=True), fn, y, args
            )
            fac = _identity_like(shape)
        else:
            fac = self._factor(fn, y, args)
        deferred = later and not explicit
        return _StageState(
            linear_state=fac,
            diffsize=jnp.array(jnp.inf, dtype=dtype),
            diffsize_prev=jnp.array(1.0, dtype=dtype),
            result=optx.RESULTS.successful,
            step=jnp.array(0),
            n_jac=jnp.array(0 if deferred else 1),
            refresh_next=jnp.array(deferred),
            y_init=y,
        )

    def step(self, fn, y, args, options, state, tags):
        del options, tags
        if self.newton:
            # Full Newton: a fresh Jacobian at the current iterate (after the first
            # iteration, which uses the one from `init`, taken at the same point).
            fac = lax.cond(
                state.step > 0,
                lambda: self._factor(fn, y, args),
                lambda: state.linear_state,
            )
            fresh = state.step > 0
        elif self.refresh:
            fac = lax.cond(
                state.refresh_next,
                lambda: self._factor(fn, y, args),
                lambda: state.linear_state,
            )
            fresh = state.refresh_next
        else:
            fac = state.linear_state
            fresh = jnp.array(False)
        fx, aux = fn(y, args)
        diff = fac.solve(fx)
        new_y = jtu.tree_map(lambda a, b: a - b, y, diff)
        dy, y_state = _to_y_units(diff, new_y, args)
        with jax.numpy_dtype_promotion("standard"):
            scaled = jtu.tree_map(
                lambda d, s: d / (self.atol + self.rtol * jnp.abs(s)), dy, y_state
            )
            diffsize = self.norm(scaled)
        diffsize = jnp.asarray(diffsize, dtype=state.diffsize.dtype)
        n_jac = state.n_jac + jnp.where(fresh, 1, 0)
        _, too_slow, rate = self._test(diffsize, state.diffsize, state.step)
        slow = (state.step >= 1) & ~(rate <= self.refresh_rate)
        # Also refresh (rather than give up) when the contraction, though below
        # `refresh_rate`, is predicted too slow to converge within `max_iters`:
        # with a stale Jacobian on a very stiff string (EA = 1e9) this prediction,
        # not a rate >= 1, is what fails most steps.
        hopeless = too_slow & (rate < 1) & self.refresh_when_hopeless
        refresh_next = (slow | hopeless) & (n_jac < self.max_jacobians) & self.refresh
        new_state = _StageState(
            linear_state=fac,
            diffsize=diffsize,
            diffsize_prev=state.diffsize,
            # (a singular or non-finite solve shows as a non-finite increment,
            # which `terminate` reports as divergence)
            result=optx.RESULTS.successful,
            step=state.step + 1,
            n_jac=n_jac,
            refresh_next=refresh_next & (not self.newton),
            # (a state passed in by diffrax comes from another stage's solve)
            y_init=jtu.tree_map(
                lambda a, b: jnp.where(state.step == 0, a, b), y, state.y_init
            ),
        )
        return new_y, new_state, aux

    def terminate(self, fn, y, args, options, state, tags):
        del fn, y, args, options, tags
        size = state.diffsize
        finite = jnp.isfinite(size)
        # (first update: no rate estimate yet; only a negligible one converges)
        converged, slow, rate = self._test(size, state.diffsize_prev, state.step - 1)
        have_rate = state.step >= 2
        if self.newton:
            diverged = ~finite | (have_rate & (rate >= 1) & (state.step >= 4))
        else:
            # A refresh scheduled for the next iteration gets its chance first.
            diverged = ~finite | (slow & ~state.refresh_next)
        started = state.step >= 1
        converged = converged & started
        diverged = diverged & ~converged & started
        linsolve_fail = (state.result != optx.RESULTS.successful) & started
        terminate = converged | diverged | linsolve_fail
        result = optx.RESULTS.where(
            diverged, optx.RESULTS.nonlinear_divergence, optx.RESULTS.successful
        )
        result = optx.RESULTS.where(linsolve_fail, state.result, result)
        return terminate, result

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        # A failed iteration returns its starting guess, not its last iterate: the
        # step is rejected either way, but differentiated (forward mode) the stage is
        # linearised at the value returned, and a diverged iterate can make that
        # linearisation non-finite, which lineax refuses with an error that ends the
        # whole solve (the slack-and-snap pendulum at its first snap, Kvaerno5).
        ok = result == optx.RESULTS.successful
        y = jtu.tree_map(lambda a, b: jnp.where(ok, a, b), y, state.y_init)
        return y, aux, {}


# --------------------------------------------------------------------------------------
# Block-diagonal (batched) linear algebra for stacked independent members

BATCHED_LINEAR_SOLVERS = {
    "batched": "auto",
    "batched_dense": "dense",
    "batched_banded": "banded",
}


class _Member(eqx.Module):
    """Member 0 of a stacked residual, as a function of one member's unknowns.

    All members are set to `u`; since members are independent, the result is
    member 0's own residual at `u` (an `eqx.Module`, so that structure detection
    can replace its array leaves by surrogates)."""

    fn: Callable
    shape: tuple = eqx.field(static=True)

    def __call__(self, u, args):
        return self.fn(jnp.broadcast_to(u, self.shape), args)[0]


class BatchedDenseFactor(eqx.Module):
    """LU factors of M independent dense blocks `(M, m, m)`."""

    lu: Any
    piv: Any

    def solve(self, rhs):
        M = rhs.shape[0]
        x = jax.vmap(lambda lu, piv, b: jax.scipy.linalg.lu_solve((lu, piv), b))(
            self.lu, self.piv, rhs.reshape(M, -1)
        )
        return x.reshape(rhs.shape)


class BatchedBandedFactor(eqx.Module):
    """Block cyclic reduction factors of M independent block-tridiagonal blocks."""

    fac: Any  # _linalg.BandedFactor with a leading member axis on its arrays

    def solve(self, rhs):
        return jax.vmap(lambda f, r: f.solve(r))(self.fac, rhs)


def batched_factor(fn, y, args, linear_solver: str = "batched", shape_only=False):
    """Factorise the Jacobian of `fn(., args)` at `y`, for a `y` of shape
    `(M, ...)` that stacks M independent members (member i of `fn` depends only on
    member i of `y`): the Jacobian is block-diagonal, so it is never formed as an
    `(M m) x (M m)` matrix.

    Every JVP seeds the same direction in all members at once, so the members'
    blocks cost as many JVPs of the stacked function as one member's Jacobian:
    m (member size) for dense blocks, 3 w b for block-tridiagonal ones (the
    structure of one member is chosen as `choose_structure` does for a single
    solve: `linear_solver` "batched" = "auto", "batched_dense", "batched_banded").
    The blocks are then factorised by a vmapped LU or block cyclic reduction.
    `shape_only`: as `StageNewton._factor`'s (the identity's Jacobian).
    """
    inner = BATCHED_LINEAR_SOLVERS[linear_solver]
    M = y.shape[0]
    member = _Member(fn, tuple(y.shape))
    width = _linalg.choose_structure(member, y[0], args, inner)
    if isinstance(width, _linalg.BorderedWidth):
        width = None  # members of a bordered structure: dense blocks
    relation = (lambda u: u) if shape_only else (lambda u: fn(u, args))
    _, lin = jax.linearize(relation, y)
    if width is None:
        m = math.prod(y.shape[1:])
        seeds = jnp.eye(m, dtype=y.dtype).reshape((m,) + y.shape[1:])
        cols = jax.vmap(lambda s: lin(jnp.broadcast_to(s, y.shape)))(seeds)
        # cols[j, i] = column j of member i's block
        blocks = jnp.moveaxis(cols.reshape(m, M, m), 0, -1)  # (M, rows, cols)
        lu, piv = jax.vmap(jax.scipy.linalg.lu_factor)(blocks)
        return BatchedDenseFactor(lu, piv)
    # Banded: the per-member extraction of `block_tridiagonal_jacobian`, vmapped
    # over the member index. `lin(broadcast(v))` does not depend on the index, so
    # vmap evaluates it once for all members.
    seed_lin = lambda v: lin(jnp.broadcast_to(v, y.shape))

    def one(i):
        mat = _linalg.block_tridiagonal_jacobian(
            None, y[0], width, linear_fn=lambda v: seed_lin(v)[i]
        )
        return _linalg.factor(mat)

    return BatchedBandedFactor(jax.vmap(one)(jnp.arange(M)))
