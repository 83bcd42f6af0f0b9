"""Solvers by name: diffrax methods with jaxstring's stage Newton iteration."""

from typing import ClassVar

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu

from .._jit import traced_once
from .bdf import BDF
from .diffrax_compat import EVERY_STAGE
from .esdirk import ESDIRK
from .fixed_step import Newmark, ThetaMethod
from .names import AUTO as AUTO, SOLVERS as SOLVERS
from .rosenbrock import Rodas5P
from .stage_newton import StageNewton


_MAX_ITERS_ADAPTIVE = 10


# diffrax's ESDIRKs take one Jacobian per step, at the predictor of their first
# implicit stage, and start every later stage's Newton iteration from it. On the
# displacement string that Jacobian is stale by the next stage (the stiff axis turns
# with the string), so each stage would refresh it at its own iterate and drop the
# refreshed Jacobian at the end of the stage (diffrax carries the step's first
# one), several factorisations per stage. Taking the Jacobian at each stage's own
# predictor instead (diffrax's `every_stage`, as for DIRK methods) costs one
# factorisation per stage and converges from there, and the step size is no longer
# held down by Newton failures (measured: docs/numerics.md, "A Jacobian per stage"
# and "Where Kvaerno5 evaluates its Jacobian"). In natural variables, whose stiff
# force is linear in the state, the step's Jacobian serves every stage and the
# extra ones only cost time, so the model chooses
# (`SolverStructure.stage_jacobians`). Where one Jacobian per step serves,
# `build_solver` gives the written-out ESDIRK of `esdirk.py` (same tableaux,
# cheaper steps: docs/numerics.md, "Kvaerno written out"); the classes below remain
# for a Jacobian per stage and for `sweep`'s lockstep mode, whose stage solves
# factorise per member (`StageNewton(linear_solver="batched")`).
class _TracedStep(eqx.Module):
    """A diffrax solver whose step is traced once per solve (`traced_once`)."""

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        return super().step(terms, t0, t1, y0, args, solver_state, made_jump)


class _StepKvaerno3(_TracedStep, dfx.Kvaerno3):
    """diffrax's Kvaerno3: one Jacobian per step."""


class _StepKvaerno4(_TracedStep, dfx.Kvaerno4):
    """diffrax's Kvaerno4: one Jacobian per step."""


class _StepKvaerno5(_TracedStep, dfx.Kvaerno5):
    """diffrax's Kvaerno5: one Jacobian per step."""


class Kvaerno3(_StepKvaerno3):
    """diffrax's Kvaerno3 with a Jacobian at every implicit stage's predictor."""

    calculate_jacobian: ClassVar = EVERY_STAGE


class Kvaerno4(_StepKvaerno4):
    """diffrax's Kvaerno4 with a Jacobian at every implicit stage's predictor."""

    calculate_jacobian: ClassVar = EVERY_STAGE


class Kvaerno5(_StepKvaerno5):
    """diffrax's Kvaerno5 with a Jacobian at every implicit stage's predictor."""

    calculate_jacobian: ClassVar = EVERY_STAGE


class ImplicitEuler(dfx.ImplicitEuler):
    """diffrax's ImplicitEuler whose failed stage Newton iteration rejects the step.

    diffrax's Runge-Kutta methods give a step whose root find failed an infinite
    error estimate, so the controller rejects it and retries a shorter one;
    diffrax's ImplicitEuler returns the failure with the finite error estimate of
    its last iterate, the step is kept, and the failure ends the solve ("maximum
    number of steps was reached in the nonlinear solver"; the case that showed it:
    docs/hard_cases.md, "What the matrix found")."""

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, y_error, dense, state, result = super().step(
            terms, t0, t1, y0, args, solver_state, made_jump
        )
        ok = result == dfx.RESULTS.successful
        y_error = jtu.tree_map(lambda e: jnp.where(ok, e, jnp.inf), y_error)
        return y1, y_error, dense, state, result


KVAERNO = {"kvaerno3": Kvaerno3, "kvaerno4": Kvaerno4, "kvaerno5": Kvaerno5}
KVAERNO_STEP_JACOBIAN = {
    "kvaerno3": _StepKvaerno3,
    "kvaerno4": _StepKvaerno4,
    "kvaerno5": _StepKvaerno5,
}


def kvaerno_class(name: str, scene):
    """The Kvaerno solver class for a name: a Jacobian per stage or per step, as
    the scene's model asks (`SolverStructure.stage_jacobians`)."""
    per_stage = scene.structure.stage_jacobians
    return (KVAERNO if per_stage else KVAERNO_STEP_JACOBIAN)[name]


def build_solver(solver, newton_rtol, newton_atol, scene, differentiable=True):
    """Return a diffrax solver for a name (tolerances may be traced arrays) and a
    scene (whose model chooses Kvaerno's Jacobian per stage or per step).
    `differentiable`: False for a solve that nothing differentiates (jaxstring's
    own solvers then trace no derivative rules)."""
    if isinstance(solver, dfx.AbstractSolver):
        return solver
    chord = StageNewton(
        rtol=newton_rtol, atol=newton_atol, max_iters=_MAX_ITERS_ADAPTIVE
    )
    if solver in KVAERNO:
        if not scene.structure.stage_jacobians:
            return ESDIRK(
                method=solver,
                rtol=newton_rtol,
                atol=newton_atol,
                differentiable=differentiable,
            )
        # A Jacobian per stage: diffrax calls `init` for each stage's solve.
        per_stage = StageNewton(
            rtol=newton_rtol,
            atol=newton_atol,
            max_iters=_MAX_ITERS_ADAPTIVE,
            first_jacobian_in_step=True,
        )
        return KVAERNO[solver](
            root_finder=per_stage, root_find_max_steps=_MAX_ITERS_ADAPTIVE
        )
    if solver == "implicit_euler":
        return ImplicitEuler(root_finder=chord, root_find_max_steps=_MAX_ITERS_ADAPTIVE)
    if solver == "implicit_euler_fixed":
        # theta = 1 with damped full Newton (see fixed_step.py): the undamped
        # StageNewton(newton=True) cycles at k = 40, EA >= 1e6, dt = 0.005.
        return ThetaMethod(theta=1.0, rtol=newton_rtol, atol=newton_atol)
    if solver == "rodas5p":
        return Rodas5P()
    if solver in ("theta", "trapezoid"):
        return ThetaMethod(theta=0.5, rtol=newton_rtol, atol=newton_atol)
    if solver == "newmark":
        return Newmark(rtol=newton_rtol, atol=newton_atol)
    if solver == "tsit5":
        return dfx.Tsit5()
    if solver == "dopri5":
        return dfx.Dopri5()
    if solver == "bdf":
        # A stored Jacobian serves later steps unless the model says its stiff
        # directions turn too fast with the state (`SolverStructure.step_jacobians`).
        reuse = not scene.structure.step_jacobians
        return BDF(
            rtol=newton_rtol,
            atol=newton_atol,
            reuse_jacobian=reuse,
            differentiable=differentiable,
        )
    raise AssertionError(solver)
