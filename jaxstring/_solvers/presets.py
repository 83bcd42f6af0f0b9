"""Accuracy presets: solver and tolerances per system, chosen from measurements.

``ACCURACY_PRESETS[name][system]`` is a dict of keyword arguments for ``simulate``
(``solver``, ``rtol``, ``atol``) and what was measured with them (``error_m``,
``cpu_s``: per measured case); ``resolve_preset(name, model)`` picks the
system of a scene's model: ``"displacement"``, ``"natural"`` (eps, t) or ``"angle"``
(eps, phi) for the string pendulum, ``"tether"``, and ``"other"`` (the tandem and
any other model).

Each preset names an end-mass error target: ``"draft"`` 1e-3 m, ``"balanced"`` 1e-5
m, ``"precise"`` 1e-7 m. For each system, the preset is the (solver, rtol = atol)
among BDF, Kvaerno5 and Rodas5P at 1e-3 ... 1e-10 that reached the target in every
measured case at the least CPU time (``experiments/race_strongest.py --presets``,
``experiments/results/race_strongest_presets.md``). Cases: the paper's pendulum,
k = 40, alpha = 0.01 s, 2 s, EA = 1e6 and 1e9 N, error = largest end-mass distance
at 0.5, 1, 1.5, 2 s from CVODE (numba right-hand side) at rtol = atol = 1e-11 in the
same variables; the paper's tether (ACEAM, 21 elements, 20 s), error of the last
element's position against Kvaerno5 at 1e-11. CPU seconds on a shared 2-core AMD
EPYC (load 6-11), one run after the compile; pendulum cells EA = 1e6 / 1e9 N. The
tandem: fishtailing (S3a) over 3000 s, error of the shuttle's position against
Kvaerno5 at 1e-11:

| system | preset | solver, rtol = atol | error, m | CPU, s |
|---|---|---|---|---|
| displacement | draft | BDF, 1e-05 | 5.0e-05 / 3.0e-06 | 0.12 / 0.29 |
| displacement | balanced | BDF, 1e-07 | 2.1e-06 / 6.8e-07 | 0.21 / 0.34 |
| displacement | precise | BDF, 1e-09 | 2.8e-08 / 2.6e-08 | 0.40 / 0.33 |
| natural (eps, t) | draft | Rodas5P, 1e-03 | 1.3e-04 / 1.4e-04 | 0.14 / 0.14 |
| natural (eps, t) | balanced | Rodas5P, 1e-05 | 2.0e-06 / 2.2e-06 | 0.32 / 0.32 |
| natural (eps, t) | precise | Rodas5P, 1e-07 | 2.1e-08 / 1.6e-08 | 0.73 / 1.04 |
| angle (eps, phi) | draft | Rodas5P, 1e-03 | 1.5e-04 / 1.3e-04 | 0.09 / 0.11 |
| angle (eps, phi) | balanced | Rodas5P, 1e-05 | 2.0e-06 / 1.5e-06 | 0.18 / 0.24 |
| angle (eps, phi) | precise | Rodas5P, 1e-07 | 2.3e-08 / 1.5e-08 | 0.43 / 0.42 |
| tether | draft | Rodas5P, 1e-04 | 2.7e-05 | 0.03 |
| tether | balanced | Rodas5P, 1e-05 | 8.1e-07 | 0.08 |
| tether | precise | Rodas5P, 1e-06 | 6.0e-08 | 0.11 |
| other (tandem) | draft | Rodas5P, 1e-06 | 6.5e-04 | 0.01 |
| other (tandem) | balanced | Rodas5P, 1e-08 | 3.5e-06 | 0.02 |
| other (tandem) | precise | Rodas5P, 1e-10 | 1.7e-08 | 0.03 |

BDF wins in displacement variables: Rodas5P loses accuracy there on the stiff
geometric nonlinearity (EA = 1e9, rtol = 1e-3: 9.3e-3 m in 3.6 s of CPU; rtol =
1e-8: failed). In natural variables Rodas5P wins, as on the tether. On the tandem,
BDF at 1e-9 (8.1e-6 m, 0.017 s) tied with Rodas5P at 1e-8 (0.018 s) for
"balanced"; the preset keeps one solver for the system. The tandem's fishtailing
amplifies errors: Rodas5P at 1e-3 is 2.5 m off after 3000 s.
"""

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
    """The system a preset is chosen for: the pendulum's formulation, "tether", or
    "other"."""
    from ..pendulum.models import AbstractString
    from ..tether.models import AbstractTether

    if isinstance(model, AbstractString):
        return model.formulation
    if isinstance(model, AbstractTether):
        return "tether"
    return "other"


def resolve_preset(name: str, model) -> dict:
    """`simulate`'s solver, rtol and atol for preset `name` on `model`."""
    preset = ACCURACY_PRESETS[name][preset_system(model)]
    return {key: preset[key] for key in ("solver", "rtol", "atol")}
