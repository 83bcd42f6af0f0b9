"""Solvers by name: diffrax methods with jaxstring's stage Newton iteration."""

import diffrax as dfx

from ._bdf import BDF
from ._fixed_step import Newmark, ThetaMethod
from ._root_finder import StageNewton
from ._rosenbrock import Rodas5P
from ._validate import check_choice


# name -> (description, adaptive step size?, implicit?)
SOLVERS = {
    "kvaerno3": ("ESDIRK order 3(2), A-L stable", True, True),
    "kvaerno4": ("ESDIRK order 4(3), A-L stable", True, True),
    "kvaerno5": ("ESDIRK order 5(4), A-L stable", True, True),
    "implicit_euler": (
        "implicit Euler, adaptive (trapezoid error estimate)",
        True,
        True,
    ),
    "implicit_euler_fixed": (
        "implicit Euler, fixed step dt0, full Newton",
        False,
        True,
    ),
    "rodas5p": (
        "Rosenbrock-Wanner Rodas5P, order 5(4), one Jacobian per step",
        True,
        True,
    ),
    "theta": (
        "theta-method, theta = 1/2 (the paper's), fixed step dt0, full Newton",
        False,
        True,
    ),
    "trapezoid": (
        "trapezoidal rule (theta = 1/2), fixed step dt0, full Newton",
        False,
        True,
    ),
    "newmark": (
        "Newmark gamma = 1/2, beta = 1/4 on (q, v), fixed step dt0, full Newton",
        False,
        True,
    ),
    "tsit5": ("explicit Tsitouras 5(4)", True, False),
    "dopri5": ("explicit Dormand-Prince 5(4)", True, False),
    "bdf": ("variable-order BDF/NDF 1-5, reused Jacobian (as CVODE)", True, True),
}

_MAX_ITERS_ADAPTIVE = 10


def check_solver(solver) -> None:
    if isinstance(solver, dfx.AbstractSolver):
        return
    check_choice("solver", solver, tuple(SOLVERS))


def is_adaptive(solver) -> bool:
    if isinstance(solver, dfx.AbstractSolver):
        return isinstance(solver, dfx.AbstractAdaptiveSolver)
    return SOLVERS[solver][1]


def build_solver(solver, newton_rtol, newton_atol):
    """Return a diffrax solver for a name (tolerances may be traced arrays)."""
    if isinstance(solver, dfx.AbstractSolver):
        return solver
    chord = StageNewton(
        rtol=newton_rtol, atol=newton_atol, max_iters=_MAX_ITERS_ADAPTIVE
    )
    if solver == "kvaerno3":
        return dfx.Kvaerno3(root_finder=chord, root_find_max_steps=_MAX_ITERS_ADAPTIVE)
    if solver == "kvaerno4":
        return dfx.Kvaerno4(root_finder=chord, root_find_max_steps=_MAX_ITERS_ADAPTIVE)
    if solver == "kvaerno5":
        return dfx.Kvaerno5(root_finder=chord, root_find_max_steps=_MAX_ITERS_ADAPTIVE)
    if solver == "implicit_euler":
        return dfx.ImplicitEuler(
            root_finder=chord, root_find_max_steps=_MAX_ITERS_ADAPTIVE
        )
    if solver == "implicit_euler_fixed":
        # theta = 1 with damped full Newton (see _fixed_step): the undamped
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
        return BDF(rtol=newton_rtol, atol=newton_atol)
    raise AssertionError(solver)
