"""Time integrators: the registry of named solvers and the project's
own stiff solvers (BDF, Rodas5P, the papers' fixed-step methods, the banded stage
Newton of the Kvaerno methods), written as diffrax solvers."""

from .bdf import BDF as BDF
from .fixed_step import Newmark as Newmark, ThetaMethod as ThetaMethod
from .registry import (
    SOLVERS as SOLVERS,
    Kvaerno3 as Kvaerno3,
    Kvaerno4 as Kvaerno4,
    Kvaerno5 as Kvaerno5,
)
from .rosenbrock import Rodas5P as Rodas5P
from .stage_newton import StageNewton as StageNewton
from .step_size import NewtonLimitedController as NewtonLimitedController
