"""jaxstring: differentiable simulation of strings, tethers and vessels in JAX."""

from . import (
    _config,  # noqa: F401  (x64 and BLAS threads, before anything else)
    scenes as scenes,
)
from ._effects import (
    AbstractEffect as AbstractEffect,
    AbstractLoad as AbstractLoad,
    AbstractTensionLaw as AbstractTensionLaw,
    Gravity as Gravity,
    KelvinVoigt as KelvinVoigt,
    Kinematics as Kinematics,
    Loads as Loads,
    Slack as Slack,
)
from ._root_finder import StageNewton as StageNewton
from ._scene import Scene as Scene
from ._simulate import simulate as simulate
from ._solvers import SOLVERS as SOLVERS
from ._string import (
    AbstractString as AbstractString,
    DisplacementString as DisplacementString,
    NaturalAngleString as NaturalAngleString,
    NaturalTangentString as NaturalTangentString,
)
from ._trajectory import Trajectory as Trajectory


__version__ = "0.1.0"
