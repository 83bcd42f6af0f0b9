"""The FPSO + shuttle tanker tandem joined by a hawser: 3-DOF manoeuvring hulls,
current, wind, turret mooring and hawser loads, equilibria and their stability,
fishtailing limit cycles, and the autopilots that keep the vessels apart.

Hulls, loads and the `Tandem` model in `vessels`, autopilots in `autopilot`, the
hawser as a lumped-mass line in `line`, the turret on a MoorDyn deck's lines in
`turret` (quasi-static catenaries, or lumped masses integrated with the vessels),
equilibria and limit cycles in `analysis`, the spec's scenes in `scenes`, figures
in `plot` (imported on demand: matplotlib).
"""

from .analysis import (
    controlled_metrics as controlled_metrics,
    find_equilibria as find_equilibria,
    find_equilibria_map as find_equilibria_map,
    hopf_sweep as hopf_sweep,
    measure_limit_cycle as measure_limit_cycle,
    pitchfork_sweep as pitchfork_sweep,
    solve_equilibrium as solve_equilibrium,
    stability as stability,
)
from .autopilot import (
    ComputedForcePD as ComputedForcePD,
    NonlinearCompensator as NonlinearCompensator,
    TandemWithIntegrator as TandemWithIntegrator,
)
from .line import (
    TandemLine as TandemLine,
    hawser_line as hawser_line,
    line_equilibrium as line_equilibrium,
    static_line as static_line,
    with_line as with_line,
)
from .scenes import (
    ENVIRONMENTS as ENVIRONMENTS,
    tandem_controlled as tandem_controlled,
    tandem_equilibria as tandem_equilibria,
    tandem_fishtail as tandem_fishtail,
    tandem_fpso_alone as tandem_fpso_alone,
    tandem_hopf as tandem_hopf,
    turret_mooring as turret_mooring,
    with_model_mismatch as with_model_mismatch,
)
from .turret import (
    MooredVessels as MooredVessels,
    TurretLines as TurretLines,
    offset_force_curve as offset_force_curve,
    turret_lines as turret_lines,
    with_dynamic_mooring as with_dynamic_mooring,
)
from .vessels import (
    HAWSER_K_H as HAWSER_K_H,
    HAWSER_L0 as HAWSER_L0,
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


__all__ = [
    "controlled_metrics",
    "find_equilibria",
    "find_equilibria_map",
    "hopf_sweep",
    "measure_limit_cycle",
    "pitchfork_sweep",
    "solve_equilibrium",
    "stability",
    "ComputedForcePD",
    "NonlinearCompensator",
    "TandemWithIntegrator",
    "TandemLine",
    "hawser_line",
    "line_equilibrium",
    "static_line",
    "with_line",
    "ENVIRONMENTS",
    "tandem_controlled",
    "tandem_equilibria",
    "tandem_fishtail",
    "tandem_fpso_alone",
    "tandem_hopf",
    "turret_mooring",
    "with_model_mismatch",
    "MooredVessels",
    "TurretLines",
    "offset_force_curve",
    "turret_lines",
    "with_dynamic_mooring",
    "AbstractActuator",
    "AbstractVesselLoad",
    "ConstantThrust",
    "Hawser",
    "Hull",
    "LinearDamping",
    "MooredFPSO",
    "OCIMFWind",
    "ShortWingCurrent",
    "Tandem",
    "TurretMooring",
    "fpso_hull",
    "make_hull",
    "shuttle_hull",
]
