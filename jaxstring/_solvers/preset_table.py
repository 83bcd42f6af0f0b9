"""The accuracy presets as measured, read from the package's table presets.json.

``presets.json`` (next to this module) is written by the benchmark that measures the
presets (``experiments/race_strongest.py --presets``, or ``--preset-table`` from its
results files): for each preset (``"draft"``, ``"balanced"``, ``"precise"``) and
system (``"displacement"``, ``"natural"``, ``"angle"``, ``"tether"``, ``"other"``)
the solver, rtol and atol, and the error (m) and CPU time (s) of each measured
case; with the stamp of the write and, per system, the results file (and its
stamp) the numbers come from.
"""

import json
import pathlib


TABLE = pathlib.Path(__file__).with_name("presets.json")


def _read(path=None) -> dict:
    return json.loads(pathlib.Path(path or TABLE).read_text())


def load_presets(path=None) -> dict:
    """The presets as ``{preset: {system: {"solver", "rtol", "atol", "error_m",
    "cpu_s"}}}`` (the measured values as tuples, one per case), the structure of
    ``jaxstring._solvers.presets.ACCURACY_PRESETS``; `path`: another table."""
    return {
        preset: {
            system: {
                "solver": entry["solver"],
                "rtol": float(entry["rtol"]),
                "atol": float(entry["atol"]),
                "error_m": tuple(float(x) for x in entry["error_m"]),
                "cpu_s": tuple(float(x) for x in entry["cpu_s"]),
            }
            for system, entry in systems.items()
        }
        for preset, systems in _read(path)["presets"].items()
    }


def preset_targets(path=None) -> dict:
    """The end-mass error each preset was chosen to reach, m."""
    return {k: float(v) for k, v in _read(path)["targets_m"].items()}


def preset_sources(path=None) -> dict:
    """Per system, the results file the table's numbers come from and its stamp;
    and under ``"table"`` the stamp of the table's own write."""
    data = _read(path)
    return {**data["sources"], "table": data["stamp"]}
