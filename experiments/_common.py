"""Shared helpers of the experiments: timing with compile apart, tables, figures,
solver selection from the registry, pendulum rows.

The clock, the stamped results writer and the measurement policies live in
``harness.py`` (re-exported here, so every script writes through the same writer).
Timing rules (project conventions): the first call of a jaxstring configuration
traces and compiles; it is reported as ``compile_s`` (first call minus the median
run) and never mixed into ``run_s``, the median of the repeats that follow. Every
comparison is a ratio of medians measured in the same process, one after the other.
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# The benchmarks time repeated runs of one compiled solve: compile without XLA:CPU's
# YNNPACK fusions, as `fit` and `sweep` do (jaxstring/_jit.py: they made the banded
# Jacobian 4-5x slower at k >= 320), unless the caller set the flag (jaxlib 0.10).
if "xla_cpu_experimental_ynn_fusion_type" not in os.environ.get("XLA_FLAGS", ""):
    try:
        from importlib.metadata import version as _version

        if _version("jaxlib").startswith("0.10."):
            os.environ["XLA_FLAGS"] = (
                os.environ.get("XLA_FLAGS", "")
                + " --xla_cpu_experimental_ynn_fusion_type="
            ).strip()
    except Exception:  # noqa: BLE001  (no jaxlib metadata: leave XLA's defaults)
        pass

import contextlib
import dataclasses
import statistics
import sys

import numpy as np
from harness import (  # noqa: F401  (re-exported: the experiments' one writer)
    LONG_RUN_S,
    MAX_STEPS,
    RESULTS,
    block,
    child_json,
    clock,
    end_mass_error,
    fmt,
    is_quick,
    new_figure,
    ref_worktree,
    results_dir,
    results_file,
    savefig,
    set_quick,
    stamp_file,
    stamp_line,
    stamp_markdown,
    write_csv,
    write_report,
    write_table,
    write_text,
)


@dataclasses.dataclass
class Timing:
    """Wall times of one configuration, s."""

    compile_s: float  # first call minus the median run (trace + compile + warm-up)
    run_s: float  # median of the repeats
    runs: list  # every repeat
    first_s: float

    @property
    def n(self) -> int:
        return len(self.runs)


def timed(fn, repeats: int = 3, long_run_s: float = LONG_RUN_S):
    """Call `fn()` once to compile and warm up, then `repeats` more times.

    Returns `(Timing, last result)`. A run longer than `long_run_s` is repeated
    once only (the table says how many repeats each median has).
    """
    out, first, _ = clock(lambda: block(fn()))
    runs = []
    for i in range(max(repeats, 1)):
        out, wall, _ = clock(lambda: block(fn()))
        runs.append(wall)
        if i == 0 and runs[0] > long_run_s:
            break
    med = statistics.median(runs)
    return Timing(max(first - med, 0.0), med, runs, first), out


def timed_split(warmup, fn, repeats: int = 3, long_run_s: float = LONG_RUN_S):
    """Like `timed`, for peers whose compile step is separate: `warmup()` is timed
    as the compile time (e.g. jit of the right-hand side), then `fn()` is repeated."""
    _, comp, _ = clock(warmup)
    runs = []
    out = None
    for i in range(max(repeats, 1)):
        out, wall, _ = clock(fn)
        runs.append(wall)
        if i == 0 and runs[0] > long_run_s:
            break
    med = statistics.median(runs)
    return Timing(comp, med, runs, comp + runs[0]), out


def solver_names(kind: str = "all", wanted=None) -> list:
    """Solver names from `jaxstring.SOLVERS`, so new solvers appear automatically.

    `kind`: "all", "adaptive", "fixed", "implicit", "explicit". `wanted`: keep only
    these names (in this order), skipping names the registry lacks.
    """
    import jaxstring

    reg = jaxstring.SOLVERS
    names = list(reg) if wanted is None else [n for n in wanted if n in reg]
    out = []
    for n in names:
        _, adaptive, implicit = reg[n][:3]
        if (
            kind == "all"
            or (kind == "adaptive" and adaptive)
            or (kind == "fixed" and not adaptive)
            or (kind == "implicit" and implicit)
            or (kind == "explicit" and not implicit)
        ):
            out.append(n)
    return out


def timing_fields(traj, compile_s, run_s, cpu_s=None) -> dict:
    """A result row's outcome and cost: ok, status, accepted steps, compile/run/CPU
    seconds."""
    return dict(
        ok=traj.ok,
        status=traj.status,
        steps=int(traj.stats["num_steps"]),
        compile_s=compile_s,
        run_s=run_s,
        cpu_s=cpu_s,
    )


def stats_dict(traj) -> dict:
    """Integer solver statistics of a Trajectory."""
    return {k: int(v) for k, v in traj.stats.items() if k != "max_steps"}


def run_jaxstring(
    scene,
    solver,
    ts,
    *,
    rtol,
    atol,
    newton_tol=None,
    dt0=None,
    repeats=3,
    max_steps=MAX_STEPS,
    label=None,
    **options,
):
    """Time `jaxstring.simulate` (compile separate, median of repeats); return a row
    dict with times, status, step counts (also as `steps`, `rejected`) and the
    end-mass trajectory (`end`). `solver` is a name or a solver object (then
    `label` names the row); `options` go to `simulate`."""
    import jaxstring

    kw = {"rtol": rtol, "atol": atol, "ts": ts, "max_steps": max_steps, **options}
    if newton_tol is not None:
        kw.update(newton_rtol=newton_tol, newton_atol=newton_tol)
    # A solver object (a variant built by a benchmark) is taken as adaptive.
    adaptive = jaxstring.SOLVERS[solver][1] if isinstance(solver, str) else True
    if dt0 is not None and not adaptive:
        kw["dt0"] = dt0
    row = {"solver": label or solver, "adaptive": adaptive}
    try:
        tm, traj = timed(lambda: jaxstring.simulate(scene, solver, **kw), repeats)
    except Exception as e:  # a solver that cannot run is a result, not a crash
        row.update(
            ok=False,
            status=f"{type(e).__name__}: {e}"[:120],
            end=None,
            compile_s=float("nan"),
            run_s=float("nan"),
            repeats=0,
        )
        return row
    row.update(
        ok=traj.ok,
        status=traj.status,
        compile_s=tm.compile_s,
        run_s=tm.run_s,
        repeats=tm.n,
        end=np.asarray(traj.end_mass) if traj.ok else None,
        **stats_dict(traj),
    )
    row.update(steps=row["num_accepted_steps"], rejected=row["num_rejected_steps"])
    return row


def parse_list(text, conv=float):
    """A comma-separated option: None when empty (the study's default), [] for
    "none"."""
    if not text:
        return None
    return [] if text == "none" else [conv(x) for x in text.split(",")]


# The comma-separated options of the pendulum studies that sweep formulations,
# stiffnesses and solvers (`run_study`'s `lists`).
PENDULUM_LISTS = {"formulations": str, "EAs": float, "solvers": str}


def run_study(main, lists=None, **options):
    """Parse a study script's command line and call `main` with it; the script's
    docstring is the command's description.

    Every study takes ``--quick`` (small sizes, results under results/quick/) and
    ``--repeats N`` (0: the study's default); `lists` maps main's keyword to the
    type of a comma-separated option (``--EAs 1e4,1e6``; empty: the default);
    `options` maps main's keyword to argparse keywords (``default``, ``type``,
    ``help``, ``choices``; the flag is ``--keyword`` unless ``flag`` names it).
    An option without ``default`` takes main's default, and without ``type`` or
    ``action`` the type of that default where it is an int or a float."""
    import argparse
    import inspect
    import sys

    doc = sys.modules[main.__module__].__doc__ or ""
    parser = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes")
    params = inspect.signature(main).parameters
    takes_repeats = "repeats" in params
    if takes_repeats:
        parser.add_argument("--repeats", type=int, default=0, help="timing repeats")
    for name in lists or {}:
        parser.add_argument(f"--{name}", default="", help="comma-separated")
    for name, kw in options.items():
        kw = dict(kw)
        given = params[name].default
        if "default" not in kw and given is not inspect.Parameter.empty:
            kw["default"] = given
        plain = type(kw.get("default")) in (int, float)
        if plain and "type" not in kw and "action" not in kw:
            kw["type"] = type(kw["default"])
        parser.add_argument(f"--{kw.pop('flag', name)}", dest=name, **kw)
    args = vars(parser.parse_args())
    for name, conv in (lists or {}).items():
        args[name] = parse_list(args[name], conv)
    if takes_repeats:
        args["repeats"] = args["repeats"] or None
    return main(**args)


def score_rows(rows, ref_end, baseline=None, **fields):
    """Add to each solver row its end-mass error against `ref_end` (`error_m`), its
    run time over the `baseline` row's (`vs_cvode`; None without a baseline that
    succeeded), the run time per attempted step (`us_per_attempt`) and `fields`;
    print one line per row."""
    base = baseline["run_s"] if baseline is not None and baseline["ok"] else None
    for r in rows:
        r.update(fields)
        r["error_m"] = (
            end_mass_error(r["end"], ref_end)
            if r.get("end") is not None
            else float("nan")
        )
        r["vs_cvode"] = (r["run_s"] / base) if (base and r.get("ok")) else None
        if r.get("steps") is not None and r.get("ok"):
            r["us_per_attempt"] = (
                1e6 * r["run_s"] / max(r["steps"] + (r.get("rejected") or 0), 1)
            )
        print(
            f"  {r['solver']:34s} ok={r.get('ok')} run={fmt(r.get('run_s'))}s "
            f"compile={fmt(r.get('compile_s'))}s steps={r.get('steps')} "
            f"rej={r.get('rejected')} err={fmt(r['error_m'])} "
            f"x CVODE={fmt(r['vs_cvode'])}",
            flush=True,
        )


@contextlib.contextmanager
def quiet_fd():
    """Silence C/C++ console output (file descriptors 1 and 2), e.g. MoorDyn's."""
    sys.stdout.flush()
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


def moordyn_start(path):
    """Create a MoorDyn system from the input file `path` and initialise it (its
    initial-condition solve; no coupled bodies): (system, seconds taken). Call it
    inside `quiet_fd()` to silence MoorDyn's console output."""
    import moordyn

    def start():
        system = moordyn.Create(path)
        moordyn.Init(system, [], [])
        return system

    system, wall, _ = clock(start)
    return system, wall


def timed_wall_cpu(fn, repeats):
    """Call `fn()` once (compile) and `repeats` times more; return (last result,
    compile s, median wall s, median CPU s of this process, all threads). The CPU
    time is the steadier measure on a shared machine."""
    out, first, _ = clock(lambda: block(fn()))
    walls, cpus = [], []
    for _ in range(repeats):
        out, w, c = clock(lambda: block(fn()))
        walls.append(w)
        cpus.append(c)
    wall = statistics.median(walls)
    return out, max(first - wall, 0.0), wall, statistics.median(cpus)


def fit_row(seed, res, wall, truth, sigma_name="sigma"):
    """One row of an identification study, printed: for each short name in
    `truth` (short name -> (parameter name, true value)) the `least_squares`
    estimate, its error in percent and its reported std; then the noise estimate
    (as `sigma_name`), iterations, solves and the fit's wall time."""
    row = dict(seed=seed, converged=res.converged)
    for short, (name, true) in truth.items():
        row[short] = res.values[name]
        row[f"{short}_err_pct"] = 100 * (res.values[name] / true - 1)
        row[f"{short}_std"] = res.std[name]
    row.update(
        {sigma_name: res.sigma},
        iterations=res.iterations,
        solves=res.solves,
        wall_s=wall,
    )
    est = ", ".join(f"{s} {row[s]:.6g} ({row[s + '_err_pct']:+.2f} %)" for s in truth)
    print(
        f"seed {seed:2d}: {est}, {res.iterations} iterations, {wall:.1f} s, "
        f"{res.message}"
    )
    return row
