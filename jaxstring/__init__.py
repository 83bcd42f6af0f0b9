"""jaxstring: differentiable simulation of strings, tethers and vessels in JAX."""

import importlib.metadata

from . import (
    _config,  # noqa: F401  (x64 and BLAS threads, before anything else)
    pendulum as pendulum,
    scenes as scenes,
    tandem as tandem,
    tether as tether,
)
from ._effect import AbstractEffect as AbstractEffect, AbstractLoad as AbstractLoad
from ._environment import (
    AbstractCurrent as AbstractCurrent,
    AbstractFlow as AbstractFlow,
    DepthProfileCurrent as DepthProfileCurrent,
    Environment as Environment,
    FunctionCurrent as FunctionCurrent,
    UniformCurrent as UniformCurrent,
)
from ._fit import (
    FitResult as FitResult,
    fit as fit,
    gauss_newton as gauss_newton,
    value_and_grad as value_and_grad,
)
from ._model import AbstractModel as AbstractModel
from ._scene import Scene as Scene
from ._simulate import SolveConfig as SolveConfig, simulate as simulate, solve as solve
from ._solvers.bdf import BDF as BDF
from ._solvers.fixed_step import Newmark as Newmark, ThetaMethod as ThetaMethod
from ._solvers.presets import ACCURACY_PRESETS as ACCURACY_PRESETS
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
from .pendulum.effects import (
    AbstractStringLoad as AbstractStringLoad,
    AbstractTensionLaw as AbstractTensionLaw,
    Gravity as Gravity,
    KelvinVoigt as KelvinVoigt,
    Kinematics as Kinematics,
    Loads as Loads,
    Slack as Slack,
)
from .pendulum.models import (
    AbstractString as AbstractString,
    DisplacementString as DisplacementString,
    NaturalAngleString as NaturalAngleString,
    NaturalTangentString as NaturalTangentString,
)
from .tandem.analysis import (
    controlled_metrics as controlled_metrics,
    find_equilibria as find_equilibria,
    find_equilibria_map as find_equilibria_map,
    hopf_sweep as hopf_sweep,
    measure_limit_cycle as measure_limit_cycle,
    pitchfork_sweep as pitchfork_sweep,
    solve_equilibrium as solve_equilibrium,
    stability as stability,
)
from .tandem.autopilot import (
    ComputedForcePD as ComputedForcePD,
    NonlinearCompensator as NonlinearCompensator,
)
from .tandem.line import (
    TandemLine as TandemLine,
    hawser_line as hawser_line,
    line_equilibrium as line_equilibrium,
    static_line as static_line,
    with_line as with_line,
)
from .tandem.vessels import (
    AbstractActuator as AbstractActuator,
    AbstractVesselLoad as AbstractVesselLoad,
    ConstantThrust as ConstantThrust,
    Hawser as Hawser,
    Hull as Hull,
    LinearDamping as LinearDamping,
    MooredFPSO as MooredFPSO,
    OCIMFWind as OCIMFWind,
    ShortWingCurrent as ShortWingCurrent,
    Tandem as Tandem,
    TurretMooring as TurretMooring,
    fpso_hull as fpso_hull,
    make_hull as make_hull,
    shuttle_hull as shuttle_hull,
)
from .tether.effects import (
    AbstractTetherLoad as AbstractTetherLoad,
    Buoyancy as Buoyancy,
    Drag as Drag,
    TetherKinematics as TetherKinematics,
    Weight as Weight,
)
from .tether.models import (
    AbstractEnd as AbstractEnd,
    AbstractTether as AbstractTether,
    AceamTether as AceamTether,
    CoupledEnd as CoupledEnd,
    EndKinematics as EndKinematics,
    ExactTether as ExactTether,
    FixedEnd as FixedEnd,
    FreeEnd as FreeEnd,
    LmsTether as LmsTether,
    PiecewiseLinear as PiecewiseLinear,
    PrescribedEnd as PrescribedEnd,
    arc_state as arc_state,
    hanging_state as hanging_state,
)


try:
    __version__ = importlib.metadata.version("jaxstring")
except importlib.metadata.PackageNotFoundError:  # a source tree, not installed
    __version__ = "0+unknown"
