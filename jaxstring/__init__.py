"""jaxstring: differentiable simulation of strings, tethers and vessels in JAX."""

import importlib.metadata

from . import (
    _config,  # noqa: F401  (x64 and BLAS threads, before anything else)
    chain as chain,
    lines as lines,
    pendulum as pendulum,
    tandem as tandem,
    tether as tether,
)
from ._config import enable_compilation_cache as enable_compilation_cache
from ._effect import AbstractEffect as AbstractEffect, AbstractLoad as AbstractLoad
from ._environment import (
    RHO_SEA_WATER as RHO_SEA_WATER,
    AbstractCurrent as AbstractCurrent,
    AbstractFlow as AbstractFlow,
    DepthProfileCurrent as DepthProfileCurrent,
    Environment as Environment,
    FunctionCurrent as FunctionCurrent,
    G as G,
    UniformCurrent as UniformCurrent,
)
from ._fit import (
    FitResult as FitResult,
    Misfit as Misfit,
    fit as fit,
    gauss_newton as gauss_newton,
    value_and_grad as value_and_grad,
)
from ._integrate import solve as solve
from ._least_squares import (
    LeastSquaresResult as LeastSquaresResult,
    least_squares as least_squares,
)
from ._model import AbstractModel as AbstractModel
from ._presets import ACCURACY_PRESETS as ACCURACY_PRESETS, preset as preset
from ._scene import Scene as Scene
from ._simulate import simulate as simulate
from ._solve_config import (
    SOLVE_DEFAULTS as SOLVE_DEFAULTS,
    SolveConfig as SolveConfig,
)
from ._solvers.bdf import BDF as BDF
from ._solvers.fixed_step import Newmark as Newmark, ThetaMethod as ThetaMethod
from ._solvers.registry import (
    SOLVERS as SOLVERS,
    Kvaerno3 as Kvaerno3,
    Kvaerno4 as Kvaerno4,
    Kvaerno5 as Kvaerno5,
)
from ._solvers.rosenbrock import Rodas5P as Rodas5P
from ._solvers.stage_newton import StageNewton as StageNewton
from ._solvers.step_size import NewtonLimitedController as NewtonLimitedController
from ._sweep import SweepResult as SweepResult, sweep as sweep
from ._trajectory import Trajectory as Trajectory

# Every system's public names, flat as well (each list lives once, in its
# namespace's `__all__`): js.DisplacementString, js.Drag, js.Tandem, ...
from .chain import *  # noqa: E402, F403
from .lines import *  # noqa: E402, F403
from .pendulum import *  # noqa: E402, F403
from .tandem import *  # noqa: E402, F403
from .tether import *  # noqa: E402, F403


try:
    __version__ = importlib.metadata.version("jaxstring")
except importlib.metadata.PackageNotFoundError:  # a source tree, not installed
    __version__ = "0+unknown"
