"""Named scenes with the source papers' default parameters (one entry point per scene).

Each system's namespace holds its own scenes (`jaxstring.pendulum.string_pendulum`,
`jaxstring.tether.tether_fixed`, `jaxstring.tandem.tandem_fishtail`, ...); this module
gathers them under one name.
"""

from .pendulum.scenes import (
    DEFAULT_PENDULUM_EFFECTS as DEFAULT_PENDULUM_EFFECTS,
    string_pendulum as string_pendulum,
)
from .tandem.scenes import (
    ENVIRONMENTS as TANDEM_ENVIRONMENTS,  # noqa: F401  (re-export)
    tandem_controlled as tandem_controlled,
    tandem_equilibria as tandem_equilibria,
    tandem_fishtail as tandem_fishtail,
    tandem_fpso_alone as tandem_fpso_alone,
    tandem_hopf as tandem_hopf,
)
from .tether.scenes import (
    tether_fixed as tether_fixed,
    tether_fold as tether_fold,
    tether_winch as tether_winch,
)
