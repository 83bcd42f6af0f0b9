"""jaxstring: differentiable simulation of strings, tethers and vessels in JAX.

`import jaxstring` turns on float64 (the one process-wide setting it makes) and
nothing else: every public name is imported on first use (PEP 562), so the import
costs little more than JAX's own.
"""

import ast
import importlib
import importlib.metadata
import pathlib
from typing import TYPE_CHECKING

from . import _config  # noqa: F401  (float64, before any JAX array exists)


SUBPACKAGES = ("chain", "lines", "pendulum", "tandem", "tether", "cli", "testing")

if TYPE_CHECKING:  # the public names, for readers and static tools; imported lazily
    from . import (
        chain as chain,
        lines as lines,
        pendulum as pendulum,
        tandem as tandem,
        tether as tether,
    )
    from ._config import (
        disable_compilation_cache as disable_compilation_cache,
        enable_compilation_cache as enable_compilation_cache,
    )
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
    from .chain import *  # noqa: F403
    from .lines import *  # noqa: F403
    from .pendulum import *  # noqa: F403
    from .tandem import *  # noqa: F403
    from .tether import *  # noqa: F403


def _lazy_names() -> dict:
    """name -> module of every public name: the imports of the block above, and
    each star-imported system's `__all__` (read from its source, not imported)."""
    here = pathlib.Path(__file__).parent
    names = {}
    tree = ast.parse((here / "__init__.py").read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If))
    for node in block.body:
        if not isinstance(node, ast.ImportFrom) or not node.module:
            continue
        module = "." + node.module
        for alias in node.names:
            if alias.name != "*":
                names.setdefault(alias.asname or alias.name, module)
                continue
            system = ast.parse((here / node.module / "__init__.py").read_text())
            for stmt in system.body:
                if isinstance(stmt, ast.Assign) and stmt.targets[0].id == "__all__":
                    for n in ast.literal_eval(stmt.value):
                        names.setdefault(n, module)
    return names


_NAMES = None


def __getattr__(name):
    global _NAMES
    if name in SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    if _NAMES is None:
        _NAMES = _lazy_names()
    if name not in _NAMES:
        raise AttributeError(f"module 'jaxstring' has no attribute {name!r}")
    value = getattr(importlib.import_module(_NAMES[name], __name__), name)
    globals()[name] = value
    return value


def __dir__():
    global _NAMES
    if _NAMES is None:
        _NAMES = _lazy_names()
    return sorted(set(globals()) | set(_NAMES) | set(SUBPACKAGES))


try:
    __version__ = importlib.metadata.version("jaxstring")
except importlib.metadata.PackageNotFoundError:  # a source tree, not installed
    __version__ = "0+unknown"
