"""The inextensible underwater tether (Blintsov): a chain of lumped masses whose
constraint tensions come from the ACEAM regulator, an exact tridiagonal solve, or
stiff LMS springs; weight, buoyancy and Morison drag in a current (the chain
loads of `jaxstring.chain`); pay-out and haul-in from a winch.

Models in `models`, the paper's scenes in `scenes`, figures in `plot` (imported on
demand: matplotlib). Ends, schedules and loads are the chain core's, re-exported
here.
"""

from ..chain import (
    AbstractEnd as AbstractEnd,
    Buoyancy as Buoyancy,
    CoupledEnd as CoupledEnd,
    Drag as Drag,
    EndKinematics as EndKinematics,
    FixedEnd as FixedEnd,
    FreeEnd as FreeEnd,
    Gravity as Gravity,
    PiecewiseLinear as PiecewiseLinear,
    PrescribedEnd as PrescribedEnd,
)
from .models import (
    AbstractTether as AbstractTether,
    AceamTether as AceamTether,
    ExactTether as ExactTether,
    LmsTether as LmsTether,
    arc_state as arc_state,
    hanging_state as hanging_state,
)
from .scenes import (
    RHO_TABLE1 as RHO_TABLE1,
    tether_fixed as tether_fixed,
    tether_fold as tether_fold,
    tether_winch as tether_winch,
)


__all__ = [
    "AbstractEnd",
    "Buoyancy",
    "CoupledEnd",
    "Drag",
    "EndKinematics",
    "FixedEnd",
    "FreeEnd",
    "Gravity",
    "PiecewiseLinear",
    "PrescribedEnd",
    "AbstractTether",
    "AceamTether",
    "ExactTether",
    "LmsTether",
    "arc_state",
    "hanging_state",
    "tether_fixed",
    "tether_fold",
    "tether_winch",
]
