"""Step-size control that learns where the stage Newton iteration stops converging.

On a stiff string a `PIDController` driving an implicit Runge-Kutta method rejects
steps for failed stage Newton iterations (`nonlinear_divergence`), not for large
error estimates: the error estimate is tiny at these steps, so the PID controller
grows the step until the Newton iteration diverges; the failed step returns an
infinite error, the controller cuts the step by `factormin` = 0.2, and the cycle
restarts, well below the Newton limit on average (measured: docs/numerics.md,
"Step-size control after a failed stage Newton solve").

`NewtonLimitedController` wraps a `PIDController` and adds what production stiff
codes do after a convergence failure (CVODE limits the growth after a failed step;
Radau5 restricts h when Newton converges slowly): after a failed nonlinear solve
(non-finite `y_error`) the step is cut by `shrink` (not 0.2), and a cap on the step
size is set just below the failed step (`margin` x h). The cap relaxes by `relax`
per accepted step, so the controller keeps probing upward, and is lifted when the
error estimate asks for less. Steps chosen by the error estimate alone are never
changed, so accuracy is the PID controller's.
"""

import diffrax as dfx
import equinox as eqx
import jax.lax as lax
import jax.numpy as jnp
import jax.tree_util as jtu
import optimistix as optx

from .esdirk import ESDIRK
from .names import STEP_CONTROLS as STEP_CONTROLS
from .rosenbrock import Rodas5P


_PID = dfx.PIDController


class NewtonLimitedController(dfx.AbstractAdaptiveStepSizeController):
    """A `PIDController` with a learned cap below the step sizes at which the
    implicit stages' Newton iteration failed.

    **Arguments:**

    - `rtol`, `atol`: as `diffrax.PIDController` (which this wraps).
    - `shrink`: step factor after a failed nonlinear solve (PID's own cut is 0.2).
    - `margin`: the cap set after a failure, as a fraction of the failed step.
    - `relax`: growth of the cap per accepted step.
    """

    rtol: float
    atol: float
    norm: object = eqx.field(static=True, default=optx.rms_norm)
    shrink: float = 0.5
    margin: float = 0.8
    relax: float = 1.02

    def __check_init__(self):
        if self.rtol is None or self.atol is None:
            raise ValueError("`rtol` and `atol` are required.")

    @property
    def _pid(self):
        return _PID(rtol=self.rtol, atol=self.atol, norm=self.norm)

    def wrap(self, direction):
        return self

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        t1_next, state = self._pid.init(terms, t0, t1, y0, dt0, args, func, error_order)
        return t1_next, (state, jnp.asarray(jnp.inf, dtype=jnp.result_type(t0, 0.0)))

    def adapt_step_size(
        self, t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state
    ):
        state, cap = controller_state
        keep, next_t0, next_t1, made_jump, state, result = self._pid.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state
        )
        leaves = jtu.tree_leaves(y_error)
        failed = ~jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))
        h = t1 - t0
        cap = lax.stop_gradient(
            jnp.where(failed, self.margin * h, jnp.where(keep, cap * self.relax, cap))
        )
        h_next = next_t1 - next_t0
        h_next = jnp.where(failed, self.shrink * h, h_next)
        h_next = jnp.minimum(h_next, cap)
        return keep, next_t0, next_t0 + h_next, made_jump, (state, cap), result


# Solvers whose implicit stages are solved by `StageNewton` and can fail a step.
NEWTON_STAGE_SOLVERS = ("kvaerno3", "kvaerno4", "kvaerno5", "implicit_euler")


# The largest step growth factor of Rodas5P's controller under step_control="auto".
ROSENBROCK_FACTORMAX = 3.0


def make_controller(
    solver, rtol, atol, adaptive=True, step_control="auto", norm=optx.rms_norm
):
    """The step-size controller `simulate` and `fit` use for `solver`:
    `ConstantStepSize` for fixed-step methods; with `step_control="auto"`,
    `NewtonLimitedController` for the ESDIRK/implicit-Euler solvers (by name, or
    any diffrax implicit Runge-Kutta instance), else `PIDController` (Rodas5P never
    fails a nonlinear solve; BDF encodes its own step choice in `y_error` for the
    plain PID controller). `"pid"` / `"newton-limited"` force one of the two.
    `norm`: the error norm (`sweep`'s lockstep mode passes its member-wise max)."""
    if not adaptive:
        return dfx.ConstantStepSize()
    newton = (
        (isinstance(solver, str) and solver in NEWTON_STAGE_SOLVERS)
        or isinstance(solver, ESDIRK)
        or (
            isinstance(solver, dfx.AbstractImplicitSolver)
            and isinstance(solver, dfx.AbstractRungeKutta)
        )
    )
    if step_control == "newton-limited" or (step_control == "auto" and newton):
        return NewtonLimitedController(rtol=rtol, atol=atol, norm=norm)
    rosenbrock = solver == "rodas5p" or isinstance(solver, Rodas5P)
    if step_control == "auto" and rosenbrock:
        # A step may grow at most 3x (diffrax's default: 10x). Where the tension-only
        # law switches elements slack and taut, a 10x growth runs the next step
        # into the kink and is rejected; on smooth scenes the cap never binds
        # (measured: docs/numerics.md, "Rodas5P").
        return _PID(rtol=rtol, atol=atol, norm=norm, factormax=ROSENBROCK_FACTORMAX)
    return _PID(rtol=rtol, atol=atol, norm=norm)
