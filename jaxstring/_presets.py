"""Accuracy presets: solver and tolerances per system, chosen from measurements.

``preset(name, scene)`` is the `SolveConfig` of preset `name` ("draft",
"balanced", "precise") for the scene's system: ``"displacement"``, ``"natural"``
(eps, t) or ``"angle"`` (eps, phi) for the string pendulum, ``"tether"``, and
``"other"`` (the tandem and any other model); a model names its system in
`AbstractModel.preset_system`.

Each preset names an end-mass (or tracked-point) error target, `PRESET_TARGETS`.
For each system the preset is the (solver, rtol = atol) that reached the target in
every measured case at the least time (``experiments/race_strongest.py
--presets``); ``ACCURACY_PRESETS[name][system]`` holds it with the measured error
(m) and time (s) per case. The measurements and their cases are on the docs'
performance page ("Accuracy presets").
"""

from ._solve_config import SolveConfig
from ._validate import check_choice


PRESET_TARGETS = {"draft": 1e-3, "balanced": 1e-5, "precise": 1e-7}
"""End-mass (or tracked-point) error each preset was chosen to reach, m."""


def _p(solver, tol, error_m, cpu_s):
    return {
        "solver": solver,
        "rtol": tol,
        "atol": tol,
        "error_m": error_m,
        "cpu_s": cpu_s,
    }


ACCURACY_PRESETS = {
    "draft": {
        "displacement": _p("bdf", 1e-5, (5.0e-5, 3.0e-6), (0.12, 0.29)),
        "natural": _p("rodas5p", 1e-3, (1.3e-4, 1.4e-4), (0.14, 0.14)),
        "angle": _p("rodas5p", 1e-3, (1.5e-4, 1.3e-4), (0.09, 0.11)),
        "tether": _p("rodas5p", 1e-4, (2.7e-5,), (0.03,)),
        "other": _p("rodas5p", 1e-6, (6.5e-4,), (0.01,)),
    },
    "balanced": {
        "displacement": _p("bdf", 1e-7, (2.1e-6, 6.8e-7), (0.21, 0.34)),
        "natural": _p("rodas5p", 1e-5, (2.0e-6, 2.2e-6), (0.32, 0.32)),
        "angle": _p("rodas5p", 1e-5, (2.0e-6, 1.5e-6), (0.18, 0.24)),
        "tether": _p("rodas5p", 1e-5, (8.1e-7,), (0.08,)),
        "other": _p("rodas5p", 1e-8, (3.5e-6,), (0.02,)),
    },
    "precise": {
        "displacement": _p("bdf", 1e-9, (2.8e-8, 2.6e-8), (0.40, 0.33)),
        "natural": _p("rodas5p", 1e-7, (2.1e-8, 1.6e-8), (0.73, 1.04)),
        "angle": _p("rodas5p", 1e-7, (2.3e-8, 1.5e-8), (0.43, 0.42)),
        "tether": _p("rodas5p", 1e-6, (6.0e-8,), (0.11,)),
        "other": _p("rodas5p", 1e-10, (1.7e-8,), (0.03,)),
    },
}


def preset_system(model) -> str:
    """The system a preset is chosen for: the model's `preset_system`."""
    return model.preset_system


def resolve_preset(name: str, model) -> dict:
    """The solver, rtol and atol of preset `name` on `model`."""
    check_choice("accuracy", name, tuple(ACCURACY_PRESETS))
    chosen = ACCURACY_PRESETS[name][preset_system(model)]
    return {key: chosen[key] for key in ("solver", "rtol", "atol")}


def preset(name: str, scene):
    """The `SolveConfig` of accuracy preset `name` ("draft", "balanced",
    "precise") for `scene`'s system: the simulate defaults with the preset's solver
    and tolerances."""
    return SolveConfig.default("simulate").replace(**resolve_preset(name, scene.model))
