"""The source paper's fixed-step "semi-professional" integrators as diffrax solvers.

* ``ThetaMethod(theta)``: y1 = y0 + h (theta f(t1, y1) + (1 - theta) f(t0, y0)).
  theta = 1/2 is the trapezoidal rule (order 2, A-stable, no damping of stiff
  modes), theta = 1 implicit Euler (order 1, L-stable); order 1 for any
  theta != 1/2.
* ``Newmark(gamma, beta)`` on the second-order form y = (q, v), q' = v, v' = a:
  q1 = q0 + h v0 + h^2 ((1/2 - beta) a0 + beta a1),  v1 = v0 + h ((1 - gamma) a0
  + gamma a1), a1 = a(t1, q1, v1). The unknown is the acceleration a1 only (half the
  size of the state). gamma = 1/2, beta = 1/4 (average acceleration) is order 2 and
  A-stable; it equals the trapezoidal rule applied to (q, v).

Both take a fixed step (use `diffrax.ConstantStepSize`; `simulate` does, with
`SolveConfig.dt0`). A fixed-step method cannot reject a step, so its nonlinear
solve must not give up early: by default (`newton="full"`) each step is solved by
damped full Newton (a fresh Jacobian at every iteration). `newton="chord"` first
tries simplified Newton updates with one factorisation of the Jacobian at the
step's start (the production stiff codes' choice) and falls back to the damped full
Newton from the step's start when they stall: it pays where the stiff force is
linear in the state (natural variables), not in displacement variables, where the
stiff axis turns with the string (see `jaxstring._solvers.stage_newton`; measured:
docs/numerics.md, "Fixed-step methods"). The Jacobian is banded for strings and
chains (the model's own where it has one, for the theta method; else a few
coloured JVPs; block cyclic reduction, ``jaxstring._linalg``), so a step stays
O(k). The iteration stops when the scaled update (atol + rtol |y|,
RMS) is below `kappa` (chord: the update times theta / (1 - theta), theta the
observed contraction rate); a step whose iteration has not converged after
`max_iters` ends the solve with a failed status (never a silently wrong result).

Newmark needs the node-major layout of the string models: the first half of the
columns of y are the positions q, the second half their rates v = q'.
"""

from typing import Any, ClassVar

import diffrax as dfx
import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp

from .. import _linalg
from .._jit import traced_once
from .._scene import Scene
from .newton import chord as newton_chord
from .stage_newton import shifted_model_jacobian


NEWTON_KINDS = ("chord", "full")
# Chord updates before falling back to full Newton: a contraction rate of 0.1 gains
# a digit per update, so 10 cover the 1e-10 Newton tolerances of the sweeps.
_CHORD_ITERS = 10


def _check_newton(newton):
    if newton not in NEWTON_KINDS:
        raise ValueError(f"`newton` must be one of {NEWTON_KINDS}; got {newton!r}.")


def _rms(x):
    return jnp.sqrt(jnp.mean(x**2))


class OneStepODESolver(dfx.AbstractSolver):
    """A one-step solver of one ODE term that keeps no state between steps."""

    term_structure: ClassVar = dfx.AbstractTerm

    def init(self, terms, t0, t1, y0, args):
        return None

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


class _ThetaResidual(eqx.Module):
    theta: float = eqx.field(static=True)

    def __call__(self, dy, a):
        t1, y0, h, f0, terms, args = a
        f1 = terms.vf(t1, y0 + dy, args)
        if f0 is None:  # theta = 1: implicit Euler
            return dy - h * f1
        return dy - h * (self.theta * f1 + (1 - self.theta) * f0)

    def model_jacobian(self, dy, a):
        """The residual's Jacobian at `dy`, `I - h theta J(t1, y0 + dy)`, from the
        model's own Jacobian (`AbstractModel.vf_jacobian`) where the ODE's `args`
        are a `Scene` whose model has one, else None (then it is probed with
        JVPs). The term is checked at run time to be the scene's vector field
        (else the matrix is NaN and the step fails loudly), as
        `stage_newton`'s stage Jacobian is."""
        t1, y0, h, _, terms, args = a
        if not (isinstance(args, Scene) and args.structure.jacobian):
            return None
        if not (jnp.shape(h) == () and jnp.shape(y0) == jnp.shape(dy)):
            return None
        y = y0 + dy
        same = lambda: jnp.array_equal(terms.vf(t1, y, args), args.vector_field(t1, y))
        return shifted_model_jacobian(args, t1, y, -h * self.theta, same)


class _NewmarkResidual(eqx.Module):
    gamma: float = eqx.field(static=True)
    beta: float = eqx.field(static=True)

    def state(self, a1, a):
        t1, q0, v0, a0, h, terms, args = a
        q1 = q0 + h * v0 + h**2 * ((0.5 - self.beta) * a0 + self.beta * a1)
        v1 = v0 + h * ((1 - self.gamma) * a0 + self.gamma * a1)
        return jnp.concatenate([q1, v1], axis=-1)

    def __call__(self, a1, a):
        t1, q0, *_ = a
        terms, args = a[5], a[6]
        m = q0.shape[-1]
        f1 = terms.vf(t1, self.state(a1, a), args)
        return a1 - f1[..., m:]


def _newton(
    residual,
    x0,
    a,
    y_of_x,
    rtol,
    atol,
    kappa,
    max_iters,
    linear_solver,
    chord_iters=0,
    x_restart=None,
    early_stop=True,
):
    """Damped full Newton for residual(x, a) = 0 from x0. Returns (x, converged).

    With `chord_iters` > 0, first up to that many simplified Newton (chord) updates
    with the one factorisation of the Jacobian at x0 (`newton.chord`, as stiff
    codes do: one factorisation per step instead of one per iteration); if they do not
    converge, the damped full Newton below restarts from x0. Either way the result
    is the step's implicit equation solved to the same test, so `newton="chord"`
    and `"full"` agree to within the Newton tolerance.

    Increments are measured in the units of the state y_of_x(x) (atol + rtol |y|,
    RMS). Damping: Deuflhard's natural monotonicity test -- a step of length lam
    is accepted when the simplified Newton correction at the new point (same
    factorisation, so scale-invariant) is smaller than (1 - lam / 2) times the
    Newton correction; otherwise lam is halved (down to 1/64). Far from the
    solution (a large fixed step on a stiff, strongly nonlinear string) plain
    Newton can cycle; the damped iteration converges. It stops when a Newton
    update is below `kappa`, or one Jacobian earlier when the simplified
    correction computed for the damping test is (then applied; see `body`).
    """
    width = _linalg.choose_structure(residual, x0, a, linear_solver)
    fn = lambda u: residual(u, a)
    own = getattr(residual, "model_jacobian", None)

    def residual_and_jacobian(x):
        """(residual, its Jacobian) at x: the model's own where the residual has
        one (`_ThetaResidual.model_jacobian`), else probed with JVPs."""
        jac = own(x, a) if own is not None and width == 1 else None
        if jac is not None:
            return fn(x), jac
        r, lin = jax.linearize(fn, x)
        return r, _linalg.jacobian(fn, x, width, lin)

    def scaled(x_from, x_to):
        dy = y_of_x(x_from) - y_of_x(x_to)
        size = _rms(dy / (atol + rtol * jnp.abs(y_of_x(x_to))))
        return jnp.where(jnp.isfinite(size), size, jnp.inf)

    # A predicted start x0 that has not converged in a quarter of the iterations,
    # or whose iteration overflowed, is dropped for the plain one `x_restart` (the
    # predictor can point the damped iteration into a slow region at a sudden
    # change of motion). Not when the two are the same start (a first step).
    restart_at = max(max_iters // 4, 1)
    if x_restart is not None:
        restart_at = jnp.where(jnp.any(x0 != x_restart), restart_at, -1)

    def body(carry):
        x, i, _ = carry
        if x_restart is not None:
            x = jnp.where(i == restart_at, x_restart, x)
        r, jac = residual_and_jacobian(x)
        fac = _linalg.factor(jac)
        dx = fac.solve(r)
        size = scaled(x, x - dx)

        def trial(lam):
            x_new = x - lam * dx
            bar = fac.solve(fn(x_new))
            return x_new, bar, scaled(x_new, x_new - bar)

        # The full step (lam = 1) is the loop's first trial, so that the program
        # holds one trial (a vector field and a solve), not two.
        def damp_cond(c):
            lam, _, _, bar_size, tried = c
            more = (bar_size > (1 - lam / 2) * size) & (lam > 1 / 64) & (size > kappa)
            return ~tried | more

        def damp_body(c):
            lam = jnp.where(c[4], c[0] / 2, c[0])
            return (lam, *trial(lam), True)

        one = jnp.ones((), size.dtype)
        start = (one, x, jnp.zeros_like(dx), jnp.asarray(jnp.inf, size.dtype), False)
        _, x_new, bar, bar_size, _ = lax.while_loop(damp_cond, damp_body, start)
        if early_stop:
            # The simplified correction `bar` at x_new is already computed (for
            # the damping test). When it is below kappa -- the test a full Newton
            # update would have to pass -- apply it and stop, instead of paying
            # one more Jacobian and factorisation for that update. (Hairer &
            # Wanner's looser theta / (1 - theta) |bar| <= kappa saves one more
            # iteration but leaves the root about kappa * tol off, so a sweep no
            # longer reproduces the loop to rounding.) Newmark passes False: with
            # it, Newmark's Newton iteration diverged on the string pendulum (not
            # understood; docs/numerics.md, "Fixed-step methods").
            done = (size > kappa) & (bar_size <= kappa)
            x_new = jnp.where(done, x_new - bar, x_new)
            size = jnp.where(done, 0.0, size)
        i_next = i + 1
        if x_restart is not None:
            overflowed = ~jnp.isfinite(size) & (i < restart_at)
            i_next = jnp.where(overflowed, restart_at, i_next)
        return x_new, i_next, size

    def cond(carry):
        _, i, size = carry
        finite = jnp.isfinite(size)
        if x_restart is not None:
            finite = finite | (i == restart_at)
        return (i < max_iters) & (size > kappa) & finite

    dtype = jnp.result_type(x0)
    big = jnp.array(1e300, dtype)
    if chord_iters > 0:
        # Simplified Newton with the one factorisation at x0 (no prediction of
        # the remaining iterations: the full Newton below takes over instead).
        fac0 = _linalg.factor(residual_and_jacobian(x0)[1])
        x_c, ok_c, _ = newton_chord(
            fn,
            fac0.solve,
            x0,
            lambda x, dx, x_new: scaled(x, x_new),
            kappa,
            chord_iters,
        )
        # Converged: the Newton loop below does not run (size 0 <= kappa).
        start = (jnp.where(ok_c, x_c, x0), 0, jnp.where(ok_c, 0.0, big))
    else:
        start = (x0, 0, big)
    x, _, size = lax.while_loop(cond, body, start)
    return x, size <= kappa


class _NewtonFixedStep(OneStepODESolver):
    """The Newton options shared by the fixed-step implicit solvers (keyword-only:
    `rtol`, `atol` the convergence test of the step's Newton iteration, `kappa` its
    contraction target, `max_iters`, `linear_solver`, `newton` = "full" or "chord")."""

    rtol: Any = eqx.field(default=1e-7, kw_only=True)
    atol: Any = eqx.field(default=1e-7, kw_only=True)
    kappa: float = eqx.field(static=True, default=0.1, kw_only=True)
    max_iters: int = eqx.field(static=True, default=100, kw_only=True)
    linear_solver: str = eqx.field(static=True, default="auto", kw_only=True)
    newton: str = eqx.field(static=True, default="full", kw_only=True)
    interpolation_cls: ClassVar = dfx.LocalLinearInterpolation

    def _solve(self, residual, x0, a, y_of_x, x_restart=None, early_stop=True):
        """The step's implicit equation residual(x, a) = 0 by `_newton` with this
        solver's options; returns (x, diffrax result)."""
        x, ok = _newton(
            residual,
            x0,
            a,
            y_of_x,
            self.rtol,
            self.atol,
            self.kappa,
            self.max_iters,
            self.linear_solver,
            _CHORD_ITERS if self.newton == "chord" else 0,
            x_restart,
            early_stop,
        )
        result = dfx.RESULTS.where(
            ok, dfx.RESULTS.successful, dfx.RESULTS.nonlinear_divergence
        )
        return x, result


class ThetaMethod(_NewtonFixedStep):
    """Theta-method with a fixed step (chord or full Newton per step).

    **Arguments:**

    - `theta`: in [0, 1]; 1/2 trapezoidal (order 2), 1 implicit Euler.
    - `rtol`, `atol`: tolerances of the Newton iteration (state units).
    - `kappa`: stop when the scaled update is below `kappa`.
    - `max_iters`: Newton iteration limit per step.
    - `linear_solver`: `"auto"`, `"dense"` or `"banded"`.
    - `newton`: `"full"` (default): damped full Newton (a fresh Jacobian every
      iteration); `"chord"`: one Jacobian and factorisation per step, at the step's
      start, reused by up to 10 simplified Newton updates, and the damped full
      Newton only when they do not converge. Both solve the step to the same test.
    - `extrapolate`: start each step's Newton iteration from the previous step's
      increment (scaled by the step ratio; zero on the first step and after a
      jump) instead of from zero, restarting from zero if that start does not
      converge in a quarter of `max_iters`. The increment changes by O(h^2 y'')
      from step to step, against O(h y') for a zero start, so fewer iterations
      are needed; the step still solves the same equation to the same test.
      Default (None): on for theta = 1 only. For theta < 1 the unresolved stiff
      components flip sign every step (amplification -(1 - theta) / theta), so
      the previous increment points the wrong way for them (measured:
      docs/numerics.md, "Fixed-step methods").
    """

    theta: float = eqx.field(static=True, default=0.5)
    extrapolate: bool | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if not 0.0 <= float(self.theta) <= 1.0:
            raise ValueError(f"`theta` must lie in [0, 1]; got {self.theta!r}.")
        _check_newton(self.newton)

    @property
    def _extrapolate(self) -> bool:
        if self.extrapolate is None:
            return float(self.theta) == 1.0
        return bool(self.extrapolate)

    def order(self, terms):
        return 2 if self.theta == 0.5 else 1

    def init(self, terms, t0, t1, y0, args):
        if not self._extrapolate:
            return None
        # (previous increment, previous step size); h = 0: no previous step.
        return jnp.zeros_like(y0), jnp.zeros((), jnp.result_type(t0, t1))

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        h = t1 - t0
        # Implicit Euler (theta = 1) does not use f(t0, y0): not evaluated.
        f0 = None if float(self.theta) == 1.0 else terms.vf(t0, y0, args)
        a = (t1, y0, h, f0, terms, args)
        res = _ThetaResidual(self.theta)
        if self._extrapolate:
            dy_prev, h_prev = solver_state
            use = (h_prev > 0) & jnp.logical_not(made_jump)
            ratio = jnp.where(use, h / jnp.where(use, h_prev, 1.0), 0.0)
            dy0 = ratio.astype(y0.dtype) * dy_prev
        else:
            dy0 = jnp.zeros_like(y0)
        restart = jnp.zeros_like(y0) if self._extrapolate else None
        dy, result = self._solve(res, dy0, a, lambda d: y0 + d, restart)
        y1 = y0 + dy
        state = (dy, h) if self._extrapolate else None
        return y1, None, dict(y0=y0, y1=y1), state, result


class Newmark(_NewtonFixedStep):
    """Newmark-beta with a fixed step, Newton (chord or full) on the acceleration.

    **Arguments:**

    - `gamma`, `beta`: Newmark parameters (default 1/2, 1/4: average acceleration,
      order 2). Order 1 when gamma != 1/2.
    - `rtol`, `atol`, `kappa`, `max_iters`, `linear_solver`, `newton`: as for
      `ThetaMethod`.

    The state's last axis is (q, v) halves with q' = v (all jaxstring strings).
    """

    gamma: float = eqx.field(static=True, default=0.5)
    beta: float = eqx.field(static=True, default=0.25)

    def __check_init__(self):
        if not (0.0 <= float(self.beta) <= 0.5 and 0.0 <= float(self.gamma) <= 1.0):
            raise ValueError(
                "Newmark needs 0 <= `beta` <= 1/2 and 0 <= `gamma` <= 1; got "
                f"beta={self.beta!r}, gamma={self.gamma!r}."
            )
        _check_newton(self.newton)

    def order(self, terms):
        return 2 if self.gamma == 0.5 else 1

    def init(self, terms, t0, t1, y0, args):
        if jnp.ndim(y0) < 1 or jnp.shape(y0)[-1] % 2:
            raise ValueError(
                "Newmark needs a state whose last axis holds positions and their "
                f"rates in two equal halves; got shape {jnp.shape(y0)}."
            )
        return None

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        h = t1 - t0
        m = y0.shape[-1] // 2
        q0, v0 = y0[..., :m], y0[..., m:]
        a0 = terms.vf(t0, y0, args)[..., m:]
        a = (t1, q0, v0, a0, h, terms, args)
        res = _NewmarkResidual(self.gamma, self.beta)
        a1, result = self._solve(
            res, a0, a, lambda acc: res.state(acc, a), early_stop=False
        )
        y1 = res.state(a1, a)
        return y1, None, dict(y0=y0, y1=y1), None, result
