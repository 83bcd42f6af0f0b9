"""Shared helpers of the experiments: timing, machine stamp, tables and figures.

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
import csv
import dataclasses
import datetime
import pathlib
import platform
import statistics
import sys
import time

import jax
import numpy as np


RESULTS = pathlib.Path(__file__).resolve().parent / "results"


# Set by `set_quick` (each script's `main(quick=...)` calls it first).
_QUICK = False


def set_quick(quick: bool) -> None:
    """Mark this process's run as a `--quick` one: its files go to results/quick/."""
    global _QUICK
    _QUICK = bool(quick)


def is_quick() -> bool:
    """A quick run: `set_quick(True)`, `--quick` on the command line, or $SMOKE_TEST."""
    return _QUICK or "--quick" in sys.argv or bool(os.environ.get("SMOKE_TEST"))


def results_dir() -> pathlib.Path:
    """Where a script writes: experiments/results/ (the latest full run of each study,
    under the study's plain name, kept in git), experiments/results/quick/ for a quick
    run (git-ignored), or $JAXSTRING_RESULTS_DIR (the smoke test: a tmp dir)."""
    if "JAXSTRING_RESULTS_DIR" in os.environ:
        out = pathlib.Path(os.environ["JAXSTRING_RESULTS_DIR"])
    else:
        out = RESULTS / "quick" if is_quick() else RESULTS
    out.mkdir(parents=True, exist_ok=True)
    return out


# One run longer than this (s) is not repeated three times (2-core shared machine):
LONG_RUN_S = 6.0


def block(x):
    """Wait for JAX work inside `x` (any PyTree) to finish."""
    return jax.block_until_ready(x)


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def command_line() -> str:
    """The command that runs this process (`python experiments/X.py ...`)."""
    return "python " + " ".join([os.path.relpath(sys.argv[0])] + sys.argv[1:])


def machine_stamp() -> dict:
    """Date, command, processor, cores, load and versions, for every results table."""
    return {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "command": command_line(),
        "processor": platform.processor() or _cpu_model() or platform.machine(),
        "cores": os.cpu_count(),
        "load_1min": round(os.getloadavg()[0], 2),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "numpy": np.__version__,
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "?"),
        "xla_flags": os.environ.get("XLA_FLAGS", "") or "-",
    }


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
    t0 = time.perf_counter()
    out = block(fn())
    first = time.perf_counter() - t0
    runs = []
    for i in range(max(repeats, 1)):
        t0 = time.perf_counter()
        out = block(fn())
        runs.append(time.perf_counter() - t0)
        if i == 0 and runs[0] > long_run_s:
            break
    med = statistics.median(runs)
    return Timing(max(first - med, 0.0), med, runs, first), out


def timed_split(warmup, fn, repeats: int = 3, long_run_s: float = LONG_RUN_S):
    """Like `timed`, for peers whose compile step is separate: `warmup()` is timed
    as the compile time (e.g. jit of the right-hand side), then `fn()` is repeated."""
    t0 = time.perf_counter()
    warmup()
    comp = time.perf_counter() - t0
    runs = []
    out = None
    for i in range(max(repeats, 1)):
        t0 = time.perf_counter()
        out = fn()
        runs.append(time.perf_counter() - t0)
        if i == 0 and runs[0] > long_run_s:
            break
    med = statistics.median(runs)
    return Timing(comp, med, runs, comp + runs[0]), out


def end_mass_error(a, b) -> float:
    """Largest distance between two end-mass trajectories `(T, dim)` (m)."""
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape != b.shape or not np.all(np.isfinite(a)):
        return float("nan")
    return float(np.max(np.linalg.norm(a - b, axis=-1)))


def fmt(x, spec=".3g") -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        if not np.isfinite(x):
            return "nan"
        return format(x, spec)
    return str(x)


def stamp_line() -> str:
    """The stamp as one line: `date: ..., command: ..., processor: ..., ...`."""
    return ", ".join(f"{k}: {v}" for k, v in machine_stamp().items())


def stamp_markdown() -> str:
    """The stamp line of a markdown table (`_date: ..., command: ..., ..._`)."""
    return f"_{stamp_line()}_"


def write_table(name: str, rows: list, columns: list, title: str, notes=()):
    """Write `results/<name>.csv` and `results/<name>.md` (stamped); print the table.

    `rows` are dicts; `columns` the keys to show, in order.
    """
    out = results_dir()
    stamp_line_ = stamp_line()
    with open(out / f"{name}.csv", "w", newline="") as f:
        f.write(f"# {title}\n# {stamp_line_}\n")
        w = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in columns})
    lines = [f"## {title}", "", f"_{stamp_line_}_", ""]
    lines += ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        lines.append("| " + " | ".join(fmt(r.get(c)) for c in columns) + " |")
    if notes:
        lines.append("")
        lines += [f"- {n}" for n in notes]
    text = "\n".join(lines) + "\n"
    (out / f"{name}.md").write_text(text)
    print(text)
    sys.stdout.flush()
    return out / f"{name}.md"


def savefig(fig, name: str):
    import matplotlib.pyplot as plt

    path = results_dir() / f"{name}.png"
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    print(f"figure: {path}")
    return path


def new_figure(ncols=1, nrows=1, w=5.0, h=3.8):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        nrows, ncols, figsize=(w * ncols, h * nrows), squeeze=False
    )
    return fig, axes


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


# One max_steps for every jaxstring run: it is static, so changing it recompiles.
MAX_STEPS = 100_000


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


def tight_reference(scene, ts, rtol=1e-10):
    """End-mass trajectory of `scene` at `ts` from Rodas5P at rtol = atol = `rtol`
    (printed with its wall time and steps)."""
    import jaxstring

    t0 = time.perf_counter()
    ref = jaxstring.simulate(
        scene, "rodas5p", rtol=rtol, atol=rtol, ts=ts, max_steps=4_000_000
    )
    print(
        f"{scene.name}: reference Rodas5P {rtol:g} in {time.perf_counter() - t0:.1f}s"
        f" ({int(ref.stats['num_accepted_steps'])} steps, {ref.status})"
    )
    return np.asarray(ref.end_mass)


def run_peer(rhs, peer, jac, ts, *, rtol, atol, repeats=3):
    """Time one external reference (see references.py) on the JAX-compiled RHS."""
    from jaxstring.testing import references

    tm, out = timed_split(
        rhs.compile, lambda: references.solve(rhs, peer, ts, rtol, atol, jac), repeats
    )
    return {
        "solver": f"{peer} [{jac}]",
        "ok": out["ok"],
        "status": "success" if out["ok"] else out["message"][:120],
        "compile_s": rhs.compile_s,
        "run_s": tm.run_s,
        "repeats": tm.n,
        "nfev": out["nfev"],
        "njev": out["njev"],
        "end": rhs.end_mass(out["ys"]) if out["ok"] else None,
    }


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


def write_report(name: str, title: str, text: str, csv_lines=()):
    """Print `text`; write it to `results/<name>.md` under `title` and the stamp,
    and `csv_lines` (strings, header first) to `results/<name>.csv`."""
    print(text)
    out = results_dir()
    (out / f"{name}.md").write_text(f"# {title}\n\n{stamp_markdown()}\n\n{text}\n")
    if csv_lines:
        (out / f"{name}.csv").write_text("\n".join(csv_lines) + "\n")


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
                1e6 * r["run_s"] / max(r["steps"] + (r["rejected"] or 0), 1)
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

    t0 = time.perf_counter()
    system = moordyn.Create(path)
    moordyn.Init(system, [], [])
    return system, time.perf_counter() - t0


def timed_wall_cpu(fn, repeats):
    """Call `fn()` once (compile) and `repeats` times more; return (last result,
    compile s, median wall s, median CPU s of this process, all threads). The CPU
    time is the steadier measure on a shared machine."""
    import jax

    def call():
        w, c = time.perf_counter(), time.process_time()
        out = jax.block_until_ready(fn())
        return out, time.perf_counter() - w, time.process_time() - c

    out, first, _ = call()
    walls, cpus = [], []
    for _ in range(repeats):
        out, w, c = call()
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


def peer_result(out, end_mass):
    """A peer solve's outcome (`peers.cvode_solve`, `references.solve`) as a row:
    status, end-mass positions (`end_mass(ys)`), right-hand-side and Jacobian calls."""
    return {
        "ok": out["ok"],
        "end": end_mass(out["ys"]) if out["ok"] else None,
        "status": "success" if out["ok"] else out["message"][:120],
        "nfev": out["nfev"],
        "njev": out["njev"],
    }


def simulate_row(scene, solver, ts, tol):
    """One `simulate` at rtol = atol = `tol` as a row: `ok`, `end` (end-mass
    positions at `ts`, or None), `status`, the solver statistics and the accepted,
    rejected and attempted steps. A solver that cannot run gives a row, not an
    exception."""
    import jaxstring

    try:
        traj = block(
            jaxstring.simulate(
                scene, solver, rtol=tol, atol=tol, ts=ts, max_steps=MAX_STEPS
            )
        )
    except Exception as e:  # noqa: BLE001  (a solver that cannot run is a result)
        return {"ok": False, "end": None, "status": f"{type(e).__name__}: {e}"}
    stats = stats_dict(traj)
    acc = stats.get("num_accepted_steps", 0)
    rej = stats.get("num_rejected_steps", 0)
    return {
        "ok": bool(traj.ok),
        "end": np.asarray(traj.end_mass) if traj.ok else None,
        "status": traj.status,
        **stats,
        "accepted": acc,
        "rejected": rej,
        "attempted": acc + rej,
    }


def clock(fn):
    """(result, wall s, process CPU s) of one call of `fn`."""
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c
