"""Accuracy presets: solver and tolerances per system, chosen from measurements.

``preset(name, scene)`` is the `SolveConfig` of preset `name` ("draft",
"balanced", "precise") for the scene's system: ``"displacement"``, ``"natural"``
(eps, t) or ``"angle"`` (eps, phi) for the string pendulum, ``"tether"``, and
``"other"`` (the tandem and any other model); a model names its system in
`AbstractModel.preset_system`.

Each preset names an end-mass (or tracked-point) error target, `PRESET_TARGETS`.
For each system the preset is the (solver, rtol = atol) that reached the target in
every measured case at the least time; ``ACCURACY_PRESETS[name][system]`` holds it
with the measured error (m) and time (s) per case, read from the table
``presets.json`` that the presets study writes (``experiments/race_strongest.py
--presets``). The measurements and their cases are on the docs' performance page
("Accuracy presets").
"""

import json
import pathlib

from ._solve_config import SolveConfig
from ._validate import check_choice


TABLE = pathlib.Path(__file__).with_name("presets.json")
"""The measured presets, written by ``experiments/race_strongest.py --presets`` (or
``--preset-table`` from its results files), with the stamp of the write and, per
system, the results file the numbers come from."""


def _read(path=None) -> dict:
    return json.loads(pathlib.Path(path or TABLE).read_text())


def load_presets(path=None) -> dict:
    """The presets as ``{preset: {system: {"solver", "rtol", "atol", "error_m",
    "cpu_s"}}}`` (the measured error, m, and time, s, of each case); `path`:
    another table."""
    return {
        name: {
            system: {
                "solver": entry["solver"],
                "rtol": float(entry["rtol"]),
                "atol": float(entry["atol"]),
                "error_m": tuple(float(x) for x in entry["error_m"]),
                "cpu_s": tuple(float(x) for x in entry["cpu_s"]),
            }
            for system, entry in systems.items()
        }
        for name, systems in _read(path)["presets"].items()
    }


def preset_targets(path=None) -> dict:
    """The end-mass error each preset was chosen to reach, m."""
    return {k: float(v) for k, v in _read(path)["targets_m"].items()}


def preset_sources(path=None) -> dict:
    """Per system, the results file the table's numbers come from and its stamp;
    under ``"table"`` the stamp of the table's own write."""
    data = _read(path)
    return {**data["sources"], "table": data["stamp"]}


ACCURACY_PRESETS = load_presets()
PRESET_TARGETS = preset_targets()
"""End-mass (or tracked-point) error each preset was chosen to reach, m."""


def preset_system(model) -> str:
    """The system a preset is chosen for: the model's `preset_system`."""
    return model.preset_system


def resolve_preset(name: str, model) -> dict:
    """The solver, rtol and atol of preset `name` on `model`."""
    check_choice("accuracy", name, tuple(ACCURACY_PRESETS))
    chosen = ACCURACY_PRESETS[name][preset_system(model)]
    return {key: chosen[key] for key in ("solver", "rtol", "atol")}


def solver_for(config, scene):
    """`config` with the solver "auto" replaced by the solver of the "balanced"
    preset of `scene`'s system (as is otherwise)."""
    if isinstance(config.solver, str) and config.solver == "auto":
        system = preset_system(scene.model)
        return config.replace(solver=ACCURACY_PRESETS["balanced"][system]["solver"])
    return config


def preset(name: str, scene):
    """The `SolveConfig` of accuracy preset `name` ("draft", "balanced",
    "precise") for `scene`'s system: the simulate defaults with the preset's solver
    and tolerances."""
    return SolveConfig.default("simulate").replace(**resolve_preset(name, scene.model))
