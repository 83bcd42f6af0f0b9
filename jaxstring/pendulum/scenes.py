"""The string pendulum of Poth et al. as a scene, with the paper's parameters."""

import math

from .._arrays import f64
from .._environment import Environment, G
from .._programs import eager_jit
from .._scene import Scene
from .._validate import (
    check_angle,
    check_choice,
    check_finite,
    check_int,
    check_nonnegative,
    check_positive,
)
from ..chain import Gravity
from .effects import EFFECTS, KelvinVoigt, Slack
from .models import FORMULATIONS


DEFAULT_PENDULUM_EFFECTS = ("gravity", "kelvin_voigt")

# The transition strain of the tension-only law that `effects=("slack",)` builds,
# per formulation: in natural variables the smoothed onset lets the string go slack
# and snap taut in far fewer steps, at a small change of the end mass; in
# displacement variables a blend that narrow stalls the implicit solvers' Newton
# iteration (the strain is a difference of positions), so the sharp law stays
# (measured: docs/pendulum.md, "Slack and snap").
SLACK_SMOOTHING = {"displacement": 0.0, "natural": 1e-7, "angle": 1e-7}


def string_pendulum(
    formulation: str = "displacement",
    k: int = 40,
    EA: float = 1e6,
    alpha: float = 0.01,
    l: float = 1.0,
    mu: float = 1.0,
    m_s: float = 1.0,
    g: float = G,
    theta0: float = math.pi / 2,
    t1: float = 2.0,
    dim: int = 2,
    effects=DEFAULT_PENDULUM_EFFECTS,
    y0=None,
    slack_smoothing=None,
) -> Scene:
    """The string pendulum of Poth et al.: a viscoelastic string with an end mass.

    **Arguments:**

    - `formulation`: `"displacement"` (eqs 11-14), `"natural"` (strain + Cartesian
      tangent, eqs 15-23, 2D/3D) or `"angle"` (strain + tangent angle, 2D).
    - `k`: number of elements (>= 2).
    - `EA`: axial stiffness, N (> 0). `alpha`: Kelvin-Voigt constant, s (>= 0).
    - `l`: unstrained length, m. `mu`: mass per length, kg/m. `m_s`: end mass, kg.
    - `g`: gravity along -y, m/s^2 (the scene's `Environment.g`).
    - `theta0`: release angle from the downward vertical, rad; pi/2 is straight and
      horizontal to the right, at rest and unstrained (the paper's figures).
    - `t1`: end time, s. `dim`: 2 or 3.
    - `effects`: names from `"gravity"`, `"kelvin_voigt"`, `"slack"` (or effect
      instances); only these are computed. Default: gravity and Kelvin-Voigt.
    - `y0`: an initial state in the model's layout, instead of the release at `theta0`.
    - `slack_smoothing`: the transition strain of the `"slack"` law (>= 0; 0: the
      sharp law); default `SLACK_SMOOTHING[formulation]`: 1e-7 in natural
      variables, the sharp law in displacement variables (see `Slack`).
    """
    check_choice("formulation", formulation, tuple(FORMULATIONS))
    check_int("k", k, 2)
    check_positive("EA", EA, "N")
    check_nonnegative("alpha", alpha, "s")
    check_positive("l", l, "m")
    check_positive("mu", mu, "kg/m")
    check_positive("m_s", m_s, "kg")
    check_nonnegative("g", g, "m/s^2")
    check_angle("theta0", theta0)
    if slack_smoothing is None:
        slack_smoothing = SLACK_SMOOTHING[formulation]
    check_nonnegative("slack_smoothing", slack_smoothing)
    check_positive("t1", t1, "s")
    if dim not in (2, 3):
        raise ValueError(f"`dim` must be 2 or 3; got {dim!r}.")
    if isinstance(effects, str):
        effects = (effects,)
    built = []
    for e in effects:
        if isinstance(e, str):
            check_choice("effect", e, tuple(EFFECTS))
            if e == "gravity":
                built.append(Gravity())
            elif e == "kelvin_voigt":
                built.append(KelvinVoigt(alpha=alpha))
            elif e == "slack":
                built.append(Slack(smoothing=float(slack_smoothing)))
        else:
            built.append(e)
    model = FORMULATIONS[formulation](l=l, mu=mu, m_s=m_s, EA=EA, k=k, dim=dim)
    if y0 is None:
        y0 = _initial_state(model, f64(theta0))
    else:
        check_finite("y0", y0)
    return Scene(
        model=model,
        effects=tuple(built),
        y0=y0,
        t1=t1,
        name=f"string-pendulum/{formulation}",
        env=Environment(g=g),
    )


@eager_jit(tiered=True)
def _initial_state(model, theta0):
    return model.initial_state(theta0)
