"""Kvaerno's ESDIRK methods (orders 3, 4, 5) written out as one compact diffrax solver.

The tableaux are diffrax's (``diffrax.Kvaerno3/4/5``: J. Kvaerno, "Singly diagonally
implicit Runge-Kutta methods with an explicit first stage", BIT 44 (2004)); the step
is written out here instead of going through diffrax's generic Runge-Kutta loop,
whose one scanned body serves every stage with masked coefficient rows, writes each
stage into a carried stage array and runs a root find that carries the
factorisation in its state. Here the stages run in one loop of attempts over a
padded tableau (one traced stage), each stage's simplified Newton iteration is one
small while loop over (f, size, status), and one factorisation of
``I - h gamma J(t0, y0)`` serves every stage of a step (all the diagonal entries
are gamma) and is not carried through a root find. The program holds one Jacobian
and one factorisation: the step's, taken at stage 1's first attempt, and a stage's
refreshed one come from the same traced call (measured against diffrax's Kvaerno,
run and compile time: docs/numerics.md, "Kvaerno written out").

Stage i solves, for its derivative f_i (f-space, as diffrax),

    f_i = f(t0 + c_i h, z_i + h gamma f_i),    z_i = y0 + h sum_{j<i} a_ij f_j,

from diffrax's stage predictor ``sum_j a_pred_ij f_j``. Convergence (Hairer &
Wanner, Solving ODEs II, IV.8), in the units of the state scaled by
``atol + rtol |y|``: converged when ``theta / (1 - theta) |dY| <= kappa`` with
theta the observed contraction rate (the first update only when it is below
``1e-3 kappa``: a stage has no rate of its own before its second update, and
accepting the first on the rate of the stage before, Radau5's test, let larger
errors through; docs/numerics.md, "Kvaerno written out"); divergent when
theta >= 1 or when the predicted error after the remaining iterations is above
kappa. A stage that fails is retried once (its second attempt) from its last iterate
with a Jacobian taken there; if that fails too the step is rejected (infinite error
estimate) and the controller (`NewtonLimitedController`) retries a shorter one.

This solver takes one Jacobian per step: the right choice where the stiff force is
linear in the state (natural variables, the tether, the tandem). Models whose stiff
directions turn within a step (`SolverStructure.stage_jacobians`: the displacement
string) run diffrax's Kvaerno with a Jacobian at every stage and `StageNewton`'s
refreshes (`registry.kvaerno_class`): written out here with a Jacobian per stage,
its Newton iteration converged at steps whose error estimate was far above the
tolerance, and the PID controller grew the step back into them after each
rejection (measured: docs/numerics.md, "Kvaerno written out").

The method is stiffly accurate (y1 is the last stage), so f(t1, y1) is the last
stage derivative, carried to the next step (FSAL); dense output is the cubic
Hermite interpolant on (y0, f0, y1, f1), as diffrax's. Gradients: each stage's
iteration is wrapped in ``jax.lax.custom_root``, so differentiation uses the exact
stage Jacobian at the solution (implicit function theorem), never the iteration.
"""

from typing import ClassVar

import diffrax as dfx
import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np

from .. import _linalg
from .._jit import traced_once
from .fixed_step import OneStepODESolver, _rms
from .newton import chord as newton_chord
from .rosenbrock import _VF


class _Tableau(eqx.Module):
    c: tuple = eqx.field(static=True)
    a: tuple = eqx.field(static=True)  # rows 1.. of a_lower
    a_pred: tuple = eqx.field(static=True)
    b_error: tuple = eqx.field(static=True)
    gamma: float = eqx.field(static=True)

    @classmethod
    def from_diffrax(cls, tab):
        diag = np.asarray(tab.a_diagonal)
        assert diag[0] == 0 and np.all(diag[1:] == diag[1]), "needs an ESDIRK"
        assert tab.fsal and np.allclose(tab.a_lower[-1], tab.b_sol[:-1])
        c = (0.0,) + tuple(float(x) for x in tab.c)
        return cls(
            c=c,
            a=tuple(tuple(float(x) for x in row) for row in tab.a_lower),
            a_pred=tuple(tuple(float(x) for x in row) for row in tab.a_predictor),
            b_error=tuple(float(x) for x in tab.b_error),
            gamma=float(diag[1]),
        )


TABLEAUX = {
    "kvaerno3": _Tableau.from_diffrax(dfx.Kvaerno3.tableau),
    "kvaerno4": _Tableau.from_diffrax(dfx.Kvaerno4.tableau),
    "kvaerno5": _Tableau.from_diffrax(dfx.Kvaerno5.tableau),
}
_ORDERS = {"kvaerno3": 3, "kvaerno4": 4, "kvaerno5": 5}


class ESDIRK(OneStepODESolver, dfx.AbstractAdaptiveSolver):
    """Kvaerno's ESDIRK 3(2), 4(3) or 5(4), one Jacobian and factorisation per step.

    **Arguments:**

    - `method`: `"kvaerno3"`, `"kvaerno4"` or `"kvaerno5"`.
    - `rtol`, `atol`: tolerances of the stage iteration, in the units of the state
      (`simulate` passes the error controller's).
    - `kappa`, `max_iters`: the stage iteration's safety factor and iteration limit.
    - `linear_solver`: `"auto"` (banded for strings and chains, dense otherwise),
      `"dense"` or `"banded"`.
    - `differentiable`: False for a solve that nothing differentiates (a saved
      program, a sweep's): the stages' iterations are then not wrapped in
      `custom_root`, which traces the derivative's linearisation and solve with
      every step, derivative or not. The same values either way.
    """

    method: str = eqx.field(static=True, default="kvaerno5")
    rtol: float = 1e-6
    atol: float = 1e-6
    kappa: float = eqx.field(static=True, default=0.05)
    max_iters: int = eqx.field(static=True, default=10)
    linear_solver: str = eqx.field(static=True, default="auto")
    differentiable: bool = eqx.field(static=True, default=True)
    interpolation_cls: ClassVar = dfx.ThirdOrderHermitePolynomialInterpolation

    def order(self, terms):
        return _ORDERS[self.method]

    def init(self, terms, t0, t1, y0, args):
        # f at the step's start: the last stage of the step before (FSAL)
        return terms.vf(t0, y0, args)

    def _factor(
        self, terms, t, y, args, hg, width, second_order, sequential, shape_only=False
    ):
        """The factorisation of I - h gamma J(t, y) (no gradient). `shape_only`:
        for its structure only (`jax.eval_shape`), from the identity's Jacobian,
        which has the same structure, without tracing the vector field's JVPs."""
        jac = _linalg.model_jacobian(terms, t, y, args) if width == 1 else None
        if jac is None:
            fn = (lambda u: u) if shape_only else (lambda u: terms.vf(t, u, args))
            jac = _linalg.jacobian(fn, y, width, None, second_order, sequential)
        return lax.stop_gradient(_linalg.factor(jac.scale_shift(1.0, -hg)))

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        tab = TABLEAUX[self.method]
        dtype = y0.dtype
        h = jnp.asarray(t1 - t0, dtype)
        hg = h * tab.gamma
        vf = _VF()
        width = _linalg.choose_structure(vf, y0, (t0, terms, args), self.linear_solver)
        second_order = _linalg.declared_second_order(vf, y0, (t0, terms, args))
        seq = _linalg.declared_sequential(vf, y0, (t0, terms, args))
        factor = lambda t, y: self._factor(
            terms, t, y, args, hg, width, second_order, seq
        )

        f0 = solver_state
        if made_jump is not False:
            f0 = lax.cond(made_jump, lambda: terms.vf(t0, y0, args), lambda: f0)
        # The stages in one loop of attempts (one traced stage, one Newton iteration
        # and one factorisation in the program, not one per stage or per case):
        # attempt 0 of stage i iterates from the predictor with the step's
        # factorisation of I - h gamma J(t0, y0) (taken at stage 1's attempt 0),
        # attempt 1 (after attempt 0 failed) from attempt 0's last iterate with a
        # Jacobian taken there. Row i of the padded tableau combines the stage
        # derivatives f_0 .. f_(i-1).
        s = len(tab.c)
        A, P = np.zeros((s, s)), np.zeros((s, s))
        for i in range(1, s):
            A[i, :i], P[i, :i] = tab.a[i - 1], tab.a_pred[i - 1]
        A, P, C = (jnp.asarray(x, dtype) for x in (A, P, np.asarray(tab.c)))
        combine = lambda row, fs: jnp.tensordot(row, fs, axes=1)
        shapes = jax.eval_shape(
            lambda: self._factor(
                terms, t0, y0, args, hg, width, second_order, seq, shape_only=True
            )
        )
        placeholder = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), shapes)

        def attempt(_, carry):
            fs, ok, i, retry, f_last, fac_step = carry
            active = i < s
            i = jnp.minimum(i, s - 1)
            z = y0 + h * combine(A[i], fs)
            ti = t0 + C[i] * h
            fresh = active & (retry | (i == 1))
            tj = jnp.where(retry, ti, t0)
            yj = jnp.where(retry, z + hg * f_last, y0)
            fac = lax.cond(fresh, lambda: factor(tj, yj), lambda: fac_step)
            fac_step = lax.cond((i == 1) & ~retry, lambda: fac, lambda: fac_step)
            f_init = jnp.where(retry, f_last, combine(P[i], fs))
            f_i, conv = lax.cond(
                active,
                lambda: self._stage(
                    terms, args, ti, z, hg, f_init, fac, width, second_order, seq
                ),
                lambda: (f_init, jnp.array(True)),
            )
            done = active & (conv | retry)
            fs = jnp.where(done, fs.at[i].set(f_i), fs)
            ok = ok & ~(done & ~conv)
            i = jnp.where(done, i + 1, jnp.where(active, i, s))
            return fs, ok, i, active & ~done, f_i, fac_step

        fs = jnp.zeros((s,) + y0.shape, dtype).at[0].set(f0)
        init = (fs, jnp.array(True), jnp.array(1), jnp.array(False), f0, placeholder)
        # at most two attempts per implicit stage
        fs, ok, *_ = lax.fori_loop(0, 2 * (s - 1), attempt, init)
        z = y0 + h * combine(A[s - 1], fs)
        # Stiffly accurate: y1 is the last stage's value, f(t1, y1) its derivative.
        y1 = z + hg * fs[-1]
        y_error = h * combine(jnp.asarray(tab.b_error, dtype), fs)
        ok = ok & jnp.all(jnp.isfinite(y1)) & jnp.all(jnp.isfinite(y_error))
        y_error = jnp.where(ok, y_error, jnp.inf)
        y1 = jnp.where(ok, y1, y0)
        f1 = jnp.where(ok, fs[-1], f0)
        dense_info = dict(y0=y0, y1=y1, k0=h * f0, k1=h * f1)
        return y1, y_error, dense_info, f1, dfx.RESULTS.successful

    def _newton(self, fn, f_init, z, hg, fac):
        """Simplified Newton on one stage with the factorisation `fac`: returns
        (f, converged). An update is measured by its effect on the stage value
        z + hg f; a negligible first update is accepted at once."""
        dtype = f_init.dtype
        rtol = jnp.asarray(self.rtol, dtype)
        atol = jnp.asarray(self.atol, dtype)
        kappa = self.kappa

        def size_of(f, d, f_new):
            return _rms(hg * d / (atol + rtol * jnp.abs(z + hg * f_new)))

        f, conv, _ = newton_chord(
            fn,
            fac.solve,
            f_init,
            size_of,
            kappa,
            self.max_iters,
            horizon=self.max_iters,
            first_tol=1e-3 * kappa,
            tiny=1e-10,
        )
        return f, conv

    def _stage(
        self, terms, args, ti, z, hg, f_init, fac, width, second_order, sequential
    ):
        """One attempt at an implicit stage: the simplified Newton iteration from
        `f_init` with the factorisation `fac`. Returns (f_i, converged)."""

        def residual(f):
            return f - terms.vf(ti, z + hg * f, args)

        def solve(fn, f_start):
            f, conv = self._newton(fn, f_start, z, hg, fac)
            # custom_root gives its aux output tangents of its own dtype, which
            # JAX refuses for booleans: pass the flag as a float.
            return f, conv.astype(f.dtype)

        def tangent_solve(g, b):
            mat = _linalg.jacobian(g, b, width, g, second_order, sequential)
            return _linalg.factor(mat).solve(b)

        if self.differentiable:
            f, conv = lax.custom_root(
                residual, f_init, solve, tangent_solve, has_aux=True
            )
        else:
            f, conv = solve(residual, f_init)
        return f, lax.stop_gradient(conv) > 0.5
