"""The names `SolveConfig` checks (solvers, step-size controls, adjoints),
without importing the solvers or diffrax (`jaxstring._lazy`)."""

from .._lazy import is_instance
from .._validate import check_choice


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


STEP_CONTROLS = ("auto", "pid", "newton-limited")

ADJOINTS = ("auto", "recursive", "direct", "backsolve", "forward", "sensitivity")


AUTO = "auto"
"""The solver name that stands for the measured choice for the scene's system (the
solver of its "balanced" accuracy preset: `jaxstring.preset`)."""


def check_solver(solver) -> None:
    if is_instance(solver, "diffrax", "AbstractSolver") or solver == AUTO:
        return
    check_choice("solver", solver, tuple(SOLVERS) + (AUTO,))


def is_adaptive(solver) -> bool:
    if is_instance(solver, "diffrax", "AbstractSolver"):
        return is_instance(solver, "diffrax", "AbstractAdaptiveSolver")
    if solver == AUTO:  # every preset's solver is adaptive
        return True
    return SOLVERS[solver][1]
