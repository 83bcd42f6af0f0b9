"""What every chain of points shares -- the tether, the mooring lines and the
tandem's line: how its ends are held and scheduled, its link geometry, and the
loads on its points (weight, buoyancy, Morison drag in a current).

Ends and schedules in `ends`, kinematics in `kinematics`, loads in `effects`.
"""

from .effects import (
    AbstractChainLoad as AbstractChainLoad,
    Buoyancy as Buoyancy,
    Drag as Drag,
    Gravity as Gravity,
)
from .ends import (
    AbstractEnd as AbstractEnd,
    CoupledEnd as CoupledEnd,
    EndKinematics as EndKinematics,
    FixedEnd as FixedEnd,
    FreeEnd as FreeEnd,
    MotionEnd as MotionEnd,
    PiecewiseLinear as PiecewiseLinear,
    PrescribedEnd as PrescribedEnd,
)
from .kinematics import (
    ChainForces as ChainForces,
    ChainKinematics as ChainKinematics,
    links as links,
    unit as unit,
)


__all__ = [
    "AbstractChainLoad",
    "Buoyancy",
    "Drag",
    "Gravity",
    "AbstractEnd",
    "CoupledEnd",
    "EndKinematics",
    "FixedEnd",
    "FreeEnd",
    "MotionEnd",
    "PiecewiseLinear",
    "PrescribedEnd",
    "ChainForces",
    "ChainKinematics",
    "links",
    "unit",
]
