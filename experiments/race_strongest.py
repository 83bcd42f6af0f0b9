"""The race against the strongest peers: time to reach an end-mass error target.

Question: at equal error, how long does jaxstring take against CVODE as an expert
sets it up? The peer is jaxstring/testing/peers.py: the same equations in numba,
CVODE BDF with the band linear solver and the analytic banded Jacobian (displacement
variables) or CVODE's banded difference quotients (natural variables), and scipy's
BDF, Radau and LSODA on the same compiled functions. CVODE driving jaxstring's own
JAX functions through Python callbacks (jaxstring/testing/references.py, band
Jacobian from JAX) is a second, labelled row.

Scene: the paper's pendulum (k = 40, alpha = 0.01 s, released horizontal, 2 s), EA =
1e6 and 1e9, displacement and (eps, phi) variables (`--formulations` adds natural
(eps, t)). Error: the largest end-mass distance at t = 0.5, 1, 1.5, 2 s from CVODE-numba
at rtol = atol = 1e-11 in the same variables. Each code runs at tolerances 1e-2 ...
1e-10 (half decades, from loose to tight, until it is past the tightest target);
its time for a target is the fastest run whose error reached it (each code at its
best tolerance). Times are the minimum over `--repeats` interleaved rounds (the first
pass times every run once; later rounds re-time, in turn, the runs that could be the
fastest for some target), wall and process CPU; compile time (jaxstring's first call,
numba's compile or cache load, JAX's jit of the callback functions) is reported apart.

Other solvers (a cheaper step, a new solver) race with `--solvers name,...`
(names from `jaxstring.SOLVERS`) and `--name variant` (files race_strongest_variant.*).

``--presets`` measures instead what jaxstring's accuracy presets rest on: Rodas5P,
Kvaerno5 and BDF at rtol = atol = 1e-3 ... 1e-10 in each pendulum formulation (EA =
1e6 and 1e9) and on the tether, and picks per system the fastest that reaches each
preset's error (race_strongest_presets.{md,csv}).

A full ``--presets`` run also writes its choice into jaxstring/presets.json
(one solver per system: the one fastest for most presets, each preset at its
cheapest tolerance that reaches the target); ``--preset-table`` rebuilds that file
from the results files race_strongest_presets{,_tandem}.csv without measuring.

``--merge a,b,...`` writes one report (race_strongest.*) from parts run as separate
processes (``--name a`` ...), e.g. one scene each.

Run: ``python experiments/race_strongest.py [--quick] [--presets]``.
"""

import itertools
import math
import os
import pathlib

import _common as common
import harness
import numpy as np

import jaxstring


FORMULATIONS = ("displacement", "angle")
EAS = (1e6, 1e9)
TARGETS = (1e-3, 1e-4, 1e-5, 1e-6)
TOLS = tuple(10.0 ** (-e / 2) for e in range(4, 21))  # 1e-2 ... 1e-10
SOLVERS = ("bdf", "kvaerno5", "rodas5p")
SCIPY = ("BDF", "Radau", "LSODA")
REF_TOL = harness.REF_TOL
CVODE = "CVODE-numba"
LABELS = {"displacement": "displacement", "natural": "(eps, t)", "angle": "(eps, phi)"}


def _codes(scene, peer, ts, solvers, scipy_methods, callback, budget_s, numba_s):
    """The contenders on one scene, CVODE-numba first (the numba codes' compile:
    `numba_s`, the peer's one warm-up)."""
    y0 = np.ravel(np.asarray(scene.y0, dtype=np.float64))
    jac = harness.peer_jacobian(peer)
    tag = "analytic band Jacobian" if jac == "analytic" else "band DQ Jacobian"
    numba = lambda: numba_s
    codes = [harness.cvode_numba_code(peer, ts, y0, warmup=numba)]
    if jac == "analytic":
        code = harness.cvode_numba_code(peer, ts, y0, jac="dq", warmup=numba)
        code.kind = "cvode-dq"
        codes.append(code)
    for name in solvers:
        codes.append(harness.jaxstring_code(scene, name, ts, label=f"jaxstring {name}"))
    for method in scipy_methods:
        codes.append(harness.scipy_numba_code(
            peer, method, ts, y0, label=f"scipy {method} [numba, {tag}]",
            cpu_limit_s=budget_s, warmup=numba,
        ))  # fmt: skip
    if callback:
        codes.append(harness.callback_code(
            scene, "cvode-BDF", ts, label="CVODE [JAX callbacks, band Jacobian]",
            max_fev=int(2e5 * budget_s),
        ))  # fmt: skip
    return codes


def race_scene(
    form,
    EA,
    *,
    k=40,
    t1=2.0,
    solvers=SOLVERS,
    scipy_methods=SCIPY,
    callback=True,
    tols=TOLS,
    targets=TARGETS,
    repeats=3,
    budget_s=10.0,
):
    """Race every code on one scene; return its rows (one per code and tolerance:
    error, minimum wall and CPU over the repeats, compile time)."""
    case = harness.PendulumCase(form, EA=EA, k=k, t1=t1)
    scene, peer = case.scene(), case.peer()
    ts = np.linspace(0.0, t1, 5)
    numba_s = peer.warmup()  # numba's compile, or its cache load
    ref, _ = harness.reference(case, ts, "cvode-numba", REF_TOL, peer=peer)
    codes = _codes(scene, peer, ts, solvers, scipy_methods, callback, budget_s, numba_s)
    load = os.getloadavg()[0]
    rows = []
    for code in codes:
        reached = 0

        def keep_going(r):
            nonlocal reached
            print(
                f"{form} EA={EA:g} {code.label:44s} tol={r['tol']:.1e} "
                f"err={r['err_m']:.2e} wall={r['wall_s']:.3f}s cpu={r['cpu_s']:.3f}s",
                flush=True,
            )
            # CPU, not wall: on a shared machine the wall time says little. A
            # failure at a loose tolerance (too large a step for the Newton
            # iteration) may pass at a tighter one: only a costly run stops.
            if r["cpu_s"] > budget_s:
                return False
            reached = reached + 1 if r["err_m"] <= min(targets) else reached
            # past the tightest target: tighter runs only cost more
            return reached < 2

        compile_s = harness.compile_seconds(code, tols[0])
        rows += harness.sweep(code, tols, ref, keep_going, compile_s=compile_s,
                              case={"formulation": form, "EA": EA})  # fmt: skip
    by_label = {c.label: c for c in codes}
    harness.retime(
        lambda: [(r, by_label[r["code"]]) for r in _candidates(rows, targets)],
        max(repeats - 1, 0),
        combine="min",
    )
    for row in rows:
        row.pop("end", None)
        row["load_start"] = load
        row["load_end"] = os.getloadavg()[0]
    return rows


def _candidates(rows, targets, slack=1.5):
    """Runs within `slack` x the fastest that reached some target, for each code."""
    out = []
    for label in dict.fromkeys(r["code"] for r in rows):
        mine = [r for r in rows if r["code"] == label and r["ok"]]
        for target in targets:
            good = [r for r in mine if r["err_m"] <= target]
            if good:
                best = min(r["wall_s"] for r in good)
                out += [r for r in good if r["wall_s"] <= slack * best]
    unique = {id(r): r for r in out}
    return list(unique.values())


def time_to_reach(rows, label, target, field="wall_s"):
    """(time, tolerance) of the fastest run of `label` within `target` (nan, nan)."""
    good = [r for r in rows if r["code"] == label and r["ok"] and r["err_m"] <= target]
    if not good:
        return math.nan, math.nan
    best = min(good, key=lambda r: r[field])
    return best[field], best["tol"]


def ratio_table(rows, forms, EAs, targets, solvers, field="wall_s"):
    """The issue's table: CVODE-numba's time, then each group's ratio to it."""
    head = "| EA, error target | " + " | ".join(f"{t:g} m" for t in targets) + " |"
    lines = [head, "|---|" + "---|" * len(targets)]
    for form in forms:
        lines.append(f"| **{LABELS[form]}** |" + " |" * len(targets))
        for EA in EAs:
            sel = [r for r in rows if r["formulation"] == form and r["EA"] == EA]
            labels = list(dict.fromkeys(r["code"] for r in sel))
            cvode = next(x for x in labels if x.startswith(CVODE))
            base = [time_to_reach(sel, cvode, t, field)[0] for t in targets]
            cells = [f"{b:.3f} s" if np.isfinite(b) else "-" for b in base]
            lines.append(f"| {EA:.0e}: {cvode} | " + " | ".join(cells) + " |")
            scipy = [x for x in labels if x.startswith("scipy")]
            js = ["jaxstring " + x for x in solvers]
            groups = [
                ("jaxstring " + " / ".join(solvers), js),
                (f"{CVODE} [band DQ Jacobian]", [
                    x for x in labels if x.startswith(CVODE) and x != cvode
                ]),
                ("scipy " + " / ".join(x.split()[1] for x in scipy), scipy),
                ("CVODE [JAX callbacks]", [x for x in labels if "JAX callbacks" in x]),
            ]  # fmt: skip
            for name, members in groups:
                members = [m for m in members if m in labels]
                if not members:
                    continue
                if name.startswith("jaxstring"):
                    name = "jaxstring " + " / ".join(m.split()[1] for m in members)
                cells = []
                for b, t in zip(base, targets):
                    parts = []
                    for m in members:
                        v = time_to_reach(sel, m, t, field)[0]
                        parts.append(f"{v / b:.2f}" if np.isfinite(v / b) else "-")
                    cells.append(" / ".join(parts) + "x")
                lines.append(f"| {EA:.0e}: {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def compile_table(rows):
    lines = ["| formulation | EA | code | compile s |", "|---|---|---|---|"]
    seen = set()
    for r in rows:
        key = (r["formulation"], r["EA"], r["code"])
        if key not in seen:
            seen.add(key)
            lines.append(
                f"| {r['formulation']} | {r['EA']:g} | {r['code']} | "
                f"{common.fmt(r['compile_s'])} |"
            )
    return "\n".join(lines)


def main(
    quick=False,
    formulations=None,
    EAs=None,
    targets=None,
    solvers=None,
    scipy=None,
    repeats=None,
    no_callback=False,
    out_name="",
):
    """Run the race; write race_strongest{_name}.{md,csv,png}; return the rows."""
    common.set_quick(quick)
    forms = formulations or (("displacement",) if quick else FORMULATIONS)
    EAs = EAs or ((1e6,) if quick else EAS)
    targets = targets or TARGETS
    solvers = solvers or (("bdf",) if quick else SOLVERS)
    scipy_methods = scipy if scipy is not None else (() if quick else SCIPY)
    repeats = repeats or (1 if quick else 3)
    k, t1 = (8, 0.5) if quick else (40, 2.0)
    rows = []
    for form in forms:
        for EA in EAs:
            rows += race_scene(
                form, EA, k=k, t1=t1, solvers=solvers, scipy_methods=scipy_methods,
                callback=not no_callback, targets=targets, repeats=repeats,
            )  # fmt: skip
    name = "race_strongest" + (f"_{out_name}" if out_name else "")
    report(rows, name, forms, EAs, targets, solvers, repeats, k, t1)
    return rows


COLUMNS = (
    "formulation EA code tol ok err_m wall_s cpu_s compile_s repeats load_start "
    "load_end"
).split()


def report(rows, name, forms, EAs, targets, solvers, repeats, k, t1, notes=()):
    """Write the tables (wall and CPU ratios, compile times) and the figure."""
    import csv
    import io

    loads = [r["load_start"] for r in rows] + [r["load_end"] for r in rows]
    text = "\n\n".join(
        [
            f"Pendulum k = {k}, alpha = 0.01 s, {t1:g} s. Time to reach each end-mass "
            f"error target (each code at its best tolerance of {len(TOLS)} from 1e-2 "
            f"to 1e-10): CVODE-numba in seconds, the others as a ratio to it "
            f"(< 1: faster). Minimum over {repeats} interleaved rounds; wall time.",
            ratio_table(rows, forms, EAs, targets, solvers, "wall_s"),
            "The same, process CPU time (all threads):",
            ratio_table(rows, forms, EAs, targets, solvers, "cpu_s"),
            "Compile time (not in the times above): jaxstring's first call minus the "
            "second; numba's compile or cache load; JAX's jit of the callbacks.",
            compile_table(rows),
            f"Error: largest end-mass distance at t = {t1 / 4:g}, {t1 / 2:g}, "
            f"{3 * t1 / 4:g}, {t1:g} s from {CVODE} at rtol = atol = {REF_TOL:g} in "
            f"the same variables. Load (1 min) during the scenes: {min(loads):.1f} to "
            f"{max(loads):.1f} on {os.cpu_count()} cores.",
            *notes,
        ]
    )
    buf = io.StringIO()
    writer = csv.DictWriter(buf, COLUMNS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    common.write_report(
        name, "Race against the strongest peers", text, buf.getvalue().splitlines()
    )
    _plot(rows, forms, EAs, name)


def _read_rows(path):
    """Rows of a race CSV (a code label may hold one unquoted comma)."""
    lines = [x for x in path.read_text().splitlines() if not x.startswith("#")]
    head = lines[0].split(",")
    rows = []
    for line in lines[1:]:
        if line.count('"'):
            import csv

            parts = next(csv.reader([line]))
        else:
            parts = line.split(",")
            extra = len(parts) - len(head)
            parts = parts[:2] + [",".join(parts[2 : 3 + extra])] + parts[3 + extra :]
        r = dict(zip(head, parts))
        for key in head:
            if key not in ("formulation", "code", "ok"):
                r[key] = float(r[key]) if r[key] not in ("", "None") else math.nan
        r["ok"] = r["ok"] == "True"
        rows.append(r)
    return rows


def merge(parts, repeats=3, solvers=SOLVERS, targets=TARGETS):
    """One report from the race's parts run as separate processes (each scene its
    own process: on a shared machine each process gets its own share of the CPU;
    a part's ratios are measured within its process)."""
    rows, stamps = [], []
    for part in parts:
        path = common.results_dir() / f"race_strongest_{part}.csv"
        rows += _read_rows(path)
        md = (common.results_dir() / f"race_strongest_{part}.md").read_text()
        stamps.append(f"- {part}: {md.splitlines()[2]}")
    forms = [f for f in FORMULATIONS + ("natural",) if any(
        r["formulation"] == f for r in rows)]  # fmt: skip
    EAs = sorted(set(r["EA"] for r in rows))
    notes = ["Parts (one process per scene):", *stamps]
    report(rows, "race_strongest", forms, EAs, targets, solvers, repeats, 40, 2.0,
           notes=notes)  # fmt: skip


PRESET_TARGETS = {"draft": 1e-3, "balanced": 1e-5, "precise": 1e-7}
PRESET_TOLS = tuple(10.0**-e for e in range(3, 11))  # 1e-3 ... 1e-10


def _js_curve(scene, solver, ts, ref, system, EA, tols, rows):
    """Error and time of one jaxstring solver over `tols` (loose to tight) until it
    is below the tightest preset target twice; rows appended to `rows`."""
    below = 0

    def keep_going(r):
        nonlocal below
        print(f"presets {system} EA={EA:g} {solver} tol={r['tol']:g} "
              f"err={r['err_m']:.2e} wall={r['wall_s']:.3f}s cpu={r['cpu_s']:.3f}s",
              flush=True)  # fmt: skip
        if not r["ok"]:
            return False
        below = below + 1 if r["err_m"] <= min(PRESET_TARGETS.values()) else below
        return below < 2

    code = harness.jaxstring_code(scene, solver, ts)
    records = harness.sweep(code, tols, ref, keep_going,
                            case={"system": system, "EA": EA})  # fmt: skip
    rows += harness.rows(records, {"code": "solver", "num_steps": "steps"})


def pick_presets(rows):
    """For each system and preset: the (solver, tol) that reaches the preset's
    target in every measured case (EA) at the least total CPU time."""
    out = {}
    for system in dict.fromkeys(r["system"] for r in rows):
        sel = [r for r in rows if r["system"] == system]
        cases = sorted(set(r["EA"] for r in sel))
        for preset, target in PRESET_TARGETS.items():
            best = None
            for key in dict.fromkeys((r["solver"], r["tol"]) for r in sel):
                hit = [
                    r for r in sel
                    if (r["solver"], r["tol"]) == key and r["ok"]
                    and r["err_m"] <= target
                ]  # fmt: skip
                if len(hit) == len(cases):
                    cost = sum(r["cpu_s"] for r in hit)
                    if best is None or cost < best[0]:
                        best = (cost, key, hit)
            out[(system, preset)] = best
    return out


# The machine-readable preset table (package data, read by
# jaxstring/_presets.py); its systems: the pendulum's formulations,
# "tether", and "other" (measured on the tandem).
PRESET_TABLE = pathlib.Path(jaxstring.__file__).parent / "presets.json"
TABLE_SYSTEM = {"tandem": "other"}


def table_picks(rows):
    """The preset table's choice per (system, preset): one solver per system, the
    one that is fastest for most of its presets (`pick_presets`), each preset at
    that solver's cheapest tolerance that reaches the target in every case (the
    fastest pick where that solver reaches none). Values as `pick_presets`."""
    picks = pick_presets(rows)
    out = {}
    for system in dict.fromkeys(r["system"] for r in rows):
        won = [b[1][0] for (s, _), b in picks.items() if s == system and b]
        if not won:
            continue
        solver = max(dict.fromkeys(won), key=won.count)
        mine = pick_presets([r for r in rows if r["system"] == system
                             and r["solver"] == solver])  # fmt: skip
        for preset in PRESET_TARGETS:
            out[(system, preset)] = mine[(system, preset)] or picks[(system, preset)]
    return out


def preset_entry(best) -> dict:
    """One table entry from a pick: solver, rtol = atol, and the error (m) and
    CPU time (s) of each measured case, rounded as the presets quote them."""
    _, (solver, tol), hit = best
    return {
        "solver": solver,
        "rtol": tol,
        "atol": tol,
        "error_m": [float(f"{r['err_m']:.1e}") for r in hit],
        "cpu_s": [round(r["cpu_s"], 2) for r in hit],
    }


def write_preset_table(entries, source, path=PRESET_TABLE):
    """Update the preset table at `path` with `entries` ({(system, preset): entry})
    measured in results file `source` (a path under experiments/results/): their
    entries, each system's source and that file's stamp, and the table's own
    stamp (date, machine, commit, command of this write)."""
    import json

    import stamps

    data = json.loads(path.read_text()) if path.exists() else {}
    data.setdefault("description", (
        "Accuracy presets of jaxstring.simulate(accuracy=...): for each preset "
        "(end-mass error target) and system, the solver and rtol = atol chosen "
        "from measurements, with the error (m) and CPU time (s) of each measured "
        "case. Written by experiments/race_strongest.py --presets; read by "
        "jaxstring/_presets.py."
    ))  # fmt: skip
    data["targets_m"] = dict(PRESET_TARGETS)
    presets = data.setdefault("presets", {})
    sources = data.setdefault("sources", {})
    measured = stamps.format_stamp(stamps.read_stamp(stamps.ROOT / source))
    for (system, preset), entry in entries.items():
        presets.setdefault(preset, {})[system] = entry
        sources[system] = {"results": source, "stamp": measured}
    fields = stamps.stamp_fields()
    data["stamp"] = {k: fields[k] for k in ("date", "machine", "commit", "command")}
    order = ("description", "targets_m", "stamp", "sources", "presets")
    data = {k: data[k] for k in order}
    path.write_text(json.dumps(data, indent=2) + "\n")
    return path


def preset_table_from_results(names=("race_strongest_presets",
                                     "race_strongest_presets_tandem")):  # fmt: skip
    """Rebuild the preset table from the presets study's results files in
    experiments/results/ (`names`: their stems), without measuring."""
    import csv

    for name in names:
        path = common.RESULTS / f"{name}.csv"
        rows = list(csv.DictReader(
            x for x in path.read_text().splitlines() if not x.startswith("#")
        ))  # fmt: skip
        for r in rows:
            r.update(EA=float(r["EA"]), tol=float(r["tol"]), ok=r["ok"] == "True",
                     err_m=float(r["err_m"]), cpu_s=float(r["cpu_s"]))  # fmt: skip
        entries = {
            (TABLE_SYSTEM.get(system, system), preset): preset_entry(best)
            for (system, preset), best in table_picks(rows).items()
            if best is not None
        }
        write_preset_table(entries, f"experiments/results/{name}.md")


def preset_study(quick=False, systems=None, out_name=""):
    """Measure jaxstring's solvers per system for the accuracy presets; write
    race_strongest_presets.{md,csv}; return the rows and the picks."""
    common.set_quick(quick)
    k, t1 = (8, 0.5) if quick else (40, 2.0)
    systems = systems or (("angle",) if quick else ("displacement", "natural",
                                                      "angle", "tether"))  # fmt: skip
    tols = PRESET_TOLS[:3] if quick else PRESET_TOLS
    rows = []
    for system in systems:
        if system in ("tandem", "tether"):
            # The tandem's fishtailing (S3a) over its first 3000 s (error: the
            # shuttle's position); the paper's tether (ACEAM, the default method),
            # 21 elements, over the still phase and the start of the rise (error:
            # the last element's position); each against Kvaerno5 at 1e-11.
            if system == "tandem":
                scene = jaxstring.tandem_fishtail(t1=600.0 if quick else 3e3)
            else:
                scene = jaxstring.tether_fixed(
                    N=11 if quick else 21, t1=12.0 if quick else 20.0
                )
            ts = np.linspace(0.0, float(scene.t1), 5)
            ref, _ = harness.reference(scene, ts, "kvaerno5", 1e-11)
            for solver in SOLVERS:
                _js_curve(scene, solver, ts, ref, system, 0.0, tols, rows)
            continue
        for EA in (1e6,) if quick else EAS:
            case = harness.PendulumCase(system, EA=EA, k=k, t1=t1)
            scene = case.scene()
            ts = np.linspace(0.0, t1, 5)
            ref, _ = harness.reference(case, ts, "cvode-numba", REF_TOL)
            for solver in SOLVERS:
                _js_curve(scene, solver, ts, ref, system, EA, tols, rows)
    picks = pick_presets(rows)
    lines = [
        "| system | preset | target | solver | rtol = atol | error (each case) | "
        "CPU s (each case) |",
        "|---|---|---|---|---|---|---|",
    ]
    for (system, preset), best in picks.items():
        if best is None:
            lines.append(f"| {system} | {preset} | {PRESET_TARGETS[preset]:g} m | "
                         "none reached | | | |")  # fmt: skip
            continue
        _, (solver, tol), hit = best
        errs = ", ".join(f"{r['err_m']:.1e}" for r in hit)
        cpus = ", ".join(f"{r['cpu_s']:.2f}" for r in hit)
        lines.append(f"| {system} | {preset} | {PRESET_TARGETS[preset]:g} m | "
                     f"{solver} | {tol:g} | {errs} m | {cpus} |")  # fmt: skip
    columns = "system EA solver tol ok err_m wall_s cpu_s steps compile_s".split()
    name = "race_strongest_presets" + (f"_{out_name}" if out_name else "")
    common.write_report(
        name,
        "Accuracy presets: the fastest solver and tolerance per system",
        "Pendulum: k = 40, alpha = 0.01 s, 2 s, EA = 1e6 and 1e9 N (cases); error "
        "= largest end-mass distance at 0.5, 1, 1.5, 2 s from CVODE-numba at "
        "rtol = atol = 1e-11 in the same variables. Tether: the paper's (ACEAM), "
        "21 elements, 20 s; error of the last element's position at 5 times "
        "against Kvaerno5 at 1e-11. Tandem: fishtailing (S3a), 3000 s; error of "
        "the shuttle's position at 5 times against Kvaerno5 at 1e-11. One timed "
        "run after the compile.\n\n" + "\n".join(lines),
        csv_lines=[",".join(columns)]
        + [",".join(str(r.get(c)) for c in columns) for r in rows],
    )
    if not quick and common.results_dir() == common.RESULTS:
        # the full run's choice goes into the package's preset table
        entries = {
            (TABLE_SYSTEM.get(system, system), preset): preset_entry(best)
            for (system, preset), best in table_picks(rows).items()
            if best is not None
        }
        write_preset_table(entries, f"experiments/results/{name}.md")
    return rows, picks


def _plot(rows, forms, EAs, name, targets=TARGETS):
    """Error against CPU time (min over rounds), one curve per code (one colour per
    code in every panel), targets dotted."""
    fig, axes = common.new_figure(len(EAs), len(forms), w=4.6, h=4.0)
    colour = {label: f"C{c % 10}" for c, label in enumerate(
        dict.fromkeys(r["code"] for r in rows))}  # fmt: skip
    handles = {}
    for (i, form), (j, EA) in itertools.product(enumerate(forms), enumerate(EAs)):
        ax = axes[i][j]
        sel = [r for r in rows if (r["formulation"], r["EA"]) == (form, EA)]
        for label in dict.fromkeys(r["code"] for r in sel):
            pts = sorted(
                (r["cpu_s"], r["err_m"])
                for r in sel
                if r["code"] == label and r["ok"] and r["err_m"] > 0
            )
            if pts:
                style = "-" if label.startswith(("jaxstring", CVODE)) else ":"
                (handles[label],) = ax.loglog(
                    *zip(*pts), style, marker="o", ms=3, color=colour[label]
                )
        for t in targets:
            ax.axhline(t, color="0.6", lw=0.6, ls=":")
        ax.set_title(f"{LABELS[form]}, EA = {EA:g} N", fontsize=9)
        ax.set(xlabel="CPU time (s), min over rounds", ylabel="end-mass error (m)")
    fig.tight_layout()
    fig.legend(handles.values(), handles.keys(), loc="upper center", fontsize=7,
               ncol=3, bbox_to_anchor=(0.5, 0.0))  # fmt: skip
    common.savefig(fig, name)


if __name__ == "__main__":
    import sys

    if "--merge" in sys.argv:
        merge(sys.argv[sys.argv.index("--merge") + 1].split(","))
        sys.exit(0)
    if "--preset-table" in sys.argv:
        # jaxstring/presets.json from the presets study's results files
        preset_table_from_results()
        sys.exit(0)
    if "--presets" in sys.argv:
        # --presets [--quick] [tandem|tether|...]: the systems to measure (a
        # subset writes race_strongest_presets_<first system>.*).
        chosen = [a for a in sys.argv[1:] if not a.startswith("--")]
        preset_study("--quick" in sys.argv, chosen or None, "_".join(chosen[:1]))
        sys.exit(0)
    common.run_study(
        main,
        lists={**common.PENDULUM_LISTS, "targets": float, "scipy": str},
        no_callback=dict(action="store_true", help="leave out CVODE on JAX callbacks"),
        out_name=dict(flag="name", default="", help="variant: race_strongest_<name>.*"),
    )
