"""The benchmark harness of the pendulum's timing studies, and the results writer of
every experiment.

A timing study is (cases x codes x tolerances) -> records:

* a **case** is one scene (`PendulumCase`: formulation, EA, k, span; its jaxstring
  scene and its numba peer);
* a **code** is one contender on a case (`Code`): a jaxstring solver
  (`jaxstring_code`), CVODE or scipy on the numba peer (`cvode_numba_code`,
  `scipy_numba_code`), or a peer on jaxstring's JAX functions through callbacks
  (`callback_code`); `code.call(tol)` runs it once and returns its outcome
  (`ok`, `status`, end-mass positions `end`, step and call counts), and
  `code.warmup()` (peers) compiles it and returns the seconds taken;
* a **record** is one run: a dict with the case's fields and `code`, `kind`,
  `tol`, `ok`, `status`, `err_m` (end-mass error against the case's reference),
  `wall_s`, `cpu_s`, `compile_s` (apart from the run), `repeats`, the step counts
  (`num_steps` attempted, `accepted`, `rejected`) and call counts (`nfev`,
  `njev`). A study renames columns where its tables always had other names
  (`rows(records, names)`).

Every time is taken by one clock (`clock`: wall and process CPU of one call); the
measurement policies differ only in how they repeat it: `repeat` (a first call,
then the median or minimum of repeats), `interleaved` (every code once per round),
`sweep` (a code over its tolerances, loose to tight, until a stop rule) and
`retime` (more rounds of chosen runs); `in_loop_us` times a piece of a step
inside one compiled loop. `reference` computes the end-mass reference of a case
(CVODE-numba, a jaxstring solver, or a callback peer, at a tight tolerance).

The writer (`write_table`, `write_report`, `write_text`, `savefig`) stamps every
file it writes (.md, .csv, .png) with the date (UTC), machine, load, git commit
and the exact command line, and with the fingerprint of the code the study
measures (studies.py; stale.py compares it with the code now).

The studies stay one script each (bench_solvers, bench_bdf, work_precision,
race_strongest, fig9_formulations, fig10_integrators, scaling_k, step_cost,
esdirk_step): each keeps its own options, its variants run as separate processes
(the race's scenes, scaling_k's starts), and the commands that the docs and the
results' stamps quote stay valid; what they share, they take from here.

Importing this module changes no setting; ``_common`` (imported first by the
studies) sets the benchmarks' thread and XLA flags.
"""

import contextlib
import csv
import dataclasses
import io
import math
import os
import pathlib
import statistics
import sys
import time

import numpy as np
import stamps
import studies


RESULTS = pathlib.Path(__file__).resolve().parent / "results"

# One run longer than this (s) is not repeated three times (2-core shared machine):
LONG_RUN_S = 6.0
# One max_steps for every jaxstring run: it is static, so changing it recompiles.
MAX_STEPS = 100_000
# The reference of the pendulum studies: CVODE-numba at this rtol = atol.
REF_TOL = 1e-11


# ---------------------------------------------------------------------------
# Where results go

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


# ---------------------------------------------------------------------------
# The clock


def clock(fn):
    """(result, wall s, process CPU s of all threads) of one call of `fn`."""
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def block(x):
    """Wait for JAX work inside `x` (any PyTree) to finish."""
    import jax

    return jax.block_until_ready(x)


def child_json(code: str, *args, env=None) -> dict:
    """Run `code` in a fresh Python process (`python -c code args...`, with `env`
    added to this process's environment) and return the JSON its last line of
    output prints: a measurement free of this process's caches."""
    import json
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", code, *map(str, args)],
        capture_output=True,
        text=True,
        check=True,
        env=dict(os.environ, **(env or {})),
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------------
# The stamp and the writer


# The commit and each study's code fingerprint, taken at this process's first
# write (the code that ran; git and parsing the sources are not free).
_CODE = {}


def stamp_line(name=None) -> str:
    """The stamp of results file `name` (e.g. ``step_cost.md``; the study that
    writes it gives the code fingerprint; without a name, no fingerprint)."""
    study = studies.study_for(name) if name else None
    if "commit" not in _CODE:
        _CODE["commit"] = stamps.git_commit()
    if study is not None and study.name not in _CODE:
        _CODE[study.name] = stamps.fingerprint(study.paths)
    fields = stamps.stamp_fields(
        study.paths if study else None,
        code=_CODE.get(study.name) if study else None,
        commit=_CODE["commit"],
    )
    return stamps.format_stamp(fields)


def stamp_markdown(name=None) -> str:
    """The stamp as the italic line of a markdown file (`_date: ..., ..._`)."""
    return f"_{stamp_line(name)}_"


def fmt(x, spec=".3g") -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        if not np.isfinite(x):
            return "nan"
        return format(x, spec)
    return str(x)


def stamp_file(path):
    """Stamp the results file at `path` (.md, .csv, .png) as written now: a stamp
    line already in it (e.g. an older one, or one without the code fingerprint)
    is replaced; otherwise a .md file gets the stamp under its first line (a
    title), a .csv file a ``# `` line on top, a .png file the text chunk
    "Stamp". For files that other code wrote (plot helpers, hand-built tables)."""
    path = pathlib.Path(path)
    line = stamp_line(path.name)
    if path.suffix == ".png":
        stamps.set_png_text(path, "Stamp", line)
        return path
    lines = path.read_text().splitlines()
    where = [i for i, x in enumerate(lines[:12]) if stamps.parse_stamp(x)]
    if path.suffix == ".md":
        if where:
            lines[where[0]] = f"_{line}_"
        else:
            lines[1:1] = ["", f"_{line}_"]
    elif where:
        lines[where[0]] = f"# {line}"
    else:
        lines.insert(0, f"# {line}")
    path.write_text("\n".join(lines) + "\n")
    return path


def write_text(filename: str, text: str):
    """Write `text` to results/`filename` and stamp it (`stamp_file`); returns the
    path."""
    path = results_dir() / filename
    path.write_text(text)
    return stamp_file(path)


@contextlib.contextmanager
def ref_worktree(ref: str):
    """The repository at commit `ref`, checked out into a temporary git worktree
    (its path), removed on exit: the code a change is measured against."""
    import subprocess
    import tempfile

    root = pathlib.Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "ref"
        git = lambda *args, check: subprocess.run(  # noqa: E731
            ["git", "worktree", *args], cwd=root, check=check, capture_output=True
        )
        git("add", "--detach", str(path), ref, check=True)
        try:
            yield path
        finally:
            git("remove", "--force", str(path), check=False)


@contextlib.contextmanager
def results_file(filename: str):
    """Open results/`filename` for writing text (a hand-built table); it is
    stamped when closed (`stamp_file`)."""
    path = results_dir() / filename
    with open(path, "w", newline="") as f:
        yield f
    stamp_file(path)


def write_csv(filename: str, rows, columns, comments=()):
    """Write `rows` (dicts) as results/`filename` (stamped; `comments` as ``# ``
    lines under the stamp); returns the path."""
    buf = io.StringIO()
    for c in comments:
        buf.write(f"# {c}\n")
    w = csv.DictWriter(buf, fieldnames=list(columns), extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({c: r.get(c, "") for c in columns})
    return write_text(filename, buf.getvalue())


def write_table(name: str, rows: list, columns: list, title: str, notes=()):
    """Write `results/<name>.csv` and `results/<name>.md` (stamped); print the table.

    `rows` are dicts; `columns` the keys to show, in order.
    """
    write_csv(f"{name}.csv", rows, columns, comments=[title])
    lines = [f"## {title}", "", stamp_markdown(f"{name}.md"), ""]
    lines += ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        lines.append("| " + " | ".join(fmt(r.get(c)) for c in columns) + " |")
    if notes:
        lines.append("")
        lines += [f"- {n}" for n in notes]
    text = "\n".join(lines) + "\n"
    path = write_text(f"{name}.md", text)
    print(text)
    sys.stdout.flush()
    return path


def write_report(name: str, title: str, text: str, csv_lines=()):
    """Print `text`; write it to `results/<name>.md` under `title` and the stamp,
    and `csv_lines` (strings, header first) to `results/<name>.csv` (stamped)."""
    print(text)
    write_text(f"{name}.md", f"# {title}\n\n{stamp_markdown(f'{name}.md')}\n\n{text}\n")
    if csv_lines:
        write_text(f"{name}.csv", "\n".join(csv_lines) + "\n")


def new_figure(ncols=1, nrows=1, w=5.0, h=3.8):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        nrows, ncols, figsize=(w * ncols, h * nrows), squeeze=False
    )
    return fig, axes


def savefig(fig, name: str, dpi=120, tight=True):
    """Save `fig` as results/<name>.png with the stamp in its text chunk "Stamp"."""
    import matplotlib.pyplot as plt

    path = results_dir() / f"{name}.png"
    kw = {"bbox_inches": "tight"} if tight else {}
    fig.savefig(path, dpi=dpi, metadata={"Stamp": stamp_line(f"{name}.png")}, **kw)
    plt.close(fig)
    print(f"figure: {path}")
    return path


# ---------------------------------------------------------------------------
# Cases, codes, outcomes, records


def end_mass_error(a, b) -> float:
    """Largest distance between two end-mass trajectories `(T, dim)` (m)."""
    if a is None or b is None:
        return float("nan")
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape != b.shape or not np.all(np.isfinite(a)):
        return float("nan")
    return float(np.max(np.linalg.norm(a - b, axis=-1)))


@dataclasses.dataclass(frozen=True)
class PendulumCase:
    """The string pendulum of Poth et al. at one formulation, EA, k and span (alpha
    = 0.01 s, released horizontal unless `y0` is given)."""

    formulation: str = "displacement"
    EA: float = 1e6
    k: int = 40
    t1: float = 2.0
    alpha: float = 0.01
    y0: object = None

    def scene(self):
        import jaxstring

        return jaxstring.string_pendulum(
            formulation=self.formulation, k=self.k, EA=self.EA, alpha=self.alpha,
            t1=self.t1, y0=self.y0,
        )  # fmt: skip

    def peer(self):
        """The numba peer of the same equations (`jaxstring.testing.peers`)."""
        from jaxstring.testing import peers

        return peers.make_rhs(self.formulation, self.k, self.EA, alpha=self.alpha)

    def fields(self) -> dict:
        return {"formulation": self.formulation, "EA": self.EA, "k": self.k}


@dataclasses.dataclass
class Code:
    """One contender on one case. `call(tol)` runs it once and returns its outcome
    dict (`ok`, `status`, `end`: end-mass positions at the save times or None,
    counts; `error`: True where it raised); `warmup()` (peers: numba's compile or
    cache load, JAX's jit of the callback functions) returns its seconds."""

    label: str
    kind: str
    call: object
    warmup: object = None


def simulate_outcome(traj) -> dict:
    """A `simulate` result as an outcome: status, end-mass positions, the solver
    statistics, and the accepted, rejected and attempted steps."""
    stats = {k: int(v) for k, v in traj.stats.items() if k != "max_steps"}
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


def peer_outcome(out, end_mass) -> dict:
    """A peer solve's outcome (`peers.cvode_solve`, `references.solve`): status,
    the peer's own message, end-mass positions (`end_mass(ys)`), right-hand-side
    and Jacobian calls."""
    return {
        "ok": out["ok"],
        "end": end_mass(out["ys"]) if out["ok"] else None,
        "status": "success" if out["ok"] else out["message"][:120],
        "message": out["message"],
        "nfev": out["nfev"],
        "njev": out["njev"],
    }


def jaxstring_code(scene, solver, ts, *, label=None, max_steps=MAX_STEPS, **kw):
    """`jaxstring.simulate(scene, solver, rtol=tol, atol=tol, ts=ts, **kw)`;
    `solver` a name of `jaxstring.SOLVERS` or a solver object (`label` names it).
    A solver that cannot run gives an outcome, not an exception."""
    import jaxstring

    def call(tol):
        try:
            traj = block(
                jaxstring.simulate(
                    scene, solver, rtol=tol, atol=tol, ts=ts, max_steps=max_steps, **kw
                )
            )
        except Exception as e:  # noqa: BLE001  (a solver that cannot run is a result)
            return {"ok": False, "end": None, "error": True,
                    "status": f"{type(e).__name__}: {e}"}  # fmt: skip
        return simulate_outcome(traj)

    return Code(label or solver, "jaxstring", call)


def _jac_tag(jac):
    return "analytic band Jacobian" if jac == "analytic" else "band DQ Jacobian"


def peer_jacobian(peer) -> str:
    """The peer's best Jacobian: "analytic" where one is written, else CVODE's
    difference quotients "dq"."""
    return "analytic" if peer.jac is not None else "dq"


def cvode_numba_code(peer, ts, y0, *, jac=None, label=None, warmup=None):
    """CVODE BDF with the band linear solver on the numba peer (CVODE-numba)."""
    from jaxstring.testing import peers

    jac = jac or peer_jacobian(peer)

    def call(tol):
        out = peers.cvode_solve(peer, ts, y0, tol, tol, jac=jac)
        return peer_outcome(out, peer.end_mass)

    return Code(label or f"CVODE-numba [{_jac_tag(jac)}]", "cvode", call,
                warmup or peer.warmup)  # fmt: skip


def scipy_numba_code(peer, method, ts, y0, *, label, jac=None, cpu_limit_s=None,
                     warmup=None):  # fmt: skip
    """scipy's solve_ivp (`method`) on the same numba functions as CVODE-numba."""
    from jaxstring.testing import peers

    jac = jac or peer_jacobian(peer)

    def call(tol):
        out = peers.scipy_solve(
            peer, method, ts, y0, tol, tol, jac=jac, cpu_limit_s=cpu_limit_s
        )
        return peer_outcome(out, peer.end_mass)

    return Code(label, "scipy", call, warmup or peer.warmup)


def callback_code(scene, peer, ts, *, label, jac="jax-band", rhs=None, **rhs_kw):
    """`peer` (a name of `jaxstring.testing.references.PEERS`) on the scene's own
    JAX vector field and Jacobian through Python callbacks."""
    from jaxstring.testing import references

    rhs = rhs or references.JaxRHS(scene, **rhs_kw)

    def call(tol):
        out = references.solve(rhs, peer, ts, tol, tol, jac)
        return peer_outcome(out, rhs.end_mass)

    code = Code(label, "callback", call, rhs.compile)
    code.rhs = rhs
    return code


def record(code, outcome, tol=None, case=None, **fields) -> dict:
    """A record of one run (the outcome's `end` kept for scoring; see the module
    docstring for the keys)."""
    r = dict(case or {})
    r.update(code=code.label, kind=code.kind, tol=tol)
    r.update({k: v for k, v in outcome.items() if k != "error"})
    r.update(fields)
    return r


def score(records, ref):
    """Add `err_m`, the end-mass error against `ref`, to each record."""
    for r in records:
        r["err_m"] = end_mass_error(r.get("end"), ref) if r.get("ok") else math.nan
    return records


def rows(records, names=None, drop=("end",)):
    """The records as table rows: keys renamed by `names` (record key -> the
    study's column name), `drop` left out."""
    names = names or {}
    return [
        {names.get(k, k): v for k, v in r.items() if k not in drop} for r in records
    ]


# ---------------------------------------------------------------------------
# Measurement policies


def _warm(code):
    """Seconds of `code.warmup()` (its return value where it gives one)."""
    out, wall, _ = clock(code.warmup)
    return out if isinstance(out, (int, float)) else wall


def repeat(code, tol=None, repeats=3, *, first=True, stat=statistics.median,
           long_run_s=LONG_RUN_S, retry_failed=True, case=None):  # fmt: skip
    """One record of `code` at `tol`: its warm-up (peers) and, where `first`, one
    untimed first call, then `repeats` timed calls (one only where the first took
    longer than `long_run_s`); wall and CPU are `stat` (median, min) of the timed
    calls. compile_s: the warm-up's seconds, else the first call less the
    statistic. A call that raised is not repeated (times nan); without
    `retry_failed`, neither is one whose first call failed (the first call's wall
    time, CPU nan, repeats 0)."""
    warm = _warm(code) if code.warmup is not None else None
    head = None
    if first or warm is None:
        out, head, _ = clock(lambda: code.call(tol))
        if not out["ok"] and not retry_failed:
            return record(code, out, tol, case, wall_s=head, cpu_s=math.nan,
                          repeats=0, compile_s=0.0 if warm is None else warm,
                          walls=[head])  # fmt: skip
        if out.get("error"):
            return record(code, out, tol, case, wall_s=math.nan, cpu_s=math.nan,
                          compile_s=math.nan, repeats=0)  # fmt: skip
    walls, cpus = [], []
    for i in range(max(repeats, 1)):
        out, w, c = clock(lambda: code.call(tol))
        walls.append(w)
        cpus.append(c)
        if i == 0 and w > long_run_s:
            break
    wall = stat(walls)
    compile_s = warm if warm is not None else max(head - wall, 0.0)
    return record(code, out, tol, case, wall_s=wall, cpu_s=stat(cpus),
                  compile_s=compile_s, repeats=len(walls), walls=walls)  # fmt: skip


def interleaved(codes, tol=None, rounds=3, *, long_run_s=LONG_RUN_S, case=None):
    """Records of `codes` at `tol` timed in interleaved rounds: one first call each
    (after its warm-up), then `rounds` rounds of one timed call per code; a code
    that failed or whose first timed call took longer than `long_run_s` sits out
    the later rounds. Wall and CPU: medians; compile_s: the warm-up's seconds,
    else the first call less the median."""
    outs, firsts, walls, cpus = {}, {}, {}, {}
    for code in codes:
        warm = _warm(code) if code.warmup is not None else None
        out, wall, _ = clock(lambda: code.call(tol))
        firsts[code.label] = wall if warm is None else warm
        outs[code.label] = out
        walls[code.label], cpus[code.label] = [], []
    for i in range(max(rounds, 1)):
        for code in codes:
            w0 = walls[code.label]
            if i > 0 and (not outs[code.label]["ok"] or w0[0] > long_run_s):
                continue
            out, w, c = clock(lambda: code.call(tol))
            w0.append(w)
            cpus[code.label].append(c)
            outs[code.label] = out
    records = []
    for code in codes:
        wall = statistics.median(walls[code.label])
        first = firsts[code.label]
        compile_s = max(first - wall, 0.0) if code.warmup is None else first
        records.append(record(
            code, outs[code.label], tol, case, wall_s=wall,
            cpu_s=statistics.median(cpus[code.label]),
            repeats=len(walls[code.label]), compile_s=compile_s,
        ))  # fmt: skip
    return records


def compile_seconds(code, tol):
    """A code's compile time: the warm-up's seconds (peers), else its first call
    less its second at `tol` (jaxstring)."""
    if code.warmup is not None:
        return _warm(code)
    _, first, _ = clock(lambda: code.call(tol))
    _, again, _ = clock(lambda: code.call(tol))
    return max(first - again, 0.0)


def sweep(code, tols, ref, keep_going, *, compile_s=None, case=None):
    """Records of `code` over `tols` (loose to tight), one timed call each, scored
    against `ref` (the first state left out: every code starts there), until
    `keep_going(record)` says no. `compile_s`: the code's compile time for every
    record; None: the first tolerance's record gets its first call less its timed
    one (an untimed first call), the others None."""
    records = []
    for i, tol in enumerate(tols):
        first = None
        if compile_s is None and i == 0:
            _, first, _ = clock(lambda: code.call(tol))
        out, wall, cpu = clock(lambda: code.call(tol))
        r = record(code, out, tol, case, wall_s=wall, cpu_s=cpu, repeats=1)
        r["compile_s"] = (
            compile_s if compile_s is not None
            else (None if first is None else max(first - wall, 0.0))
        )  # fmt: skip
        end = r.get("end")
        r["err_m"] = end_mass_error(end[1:], ref[1:]) if end is not None else math.nan
        records.append(r)
        if not keep_going(r):
            break
    return records


def retime(select, rounds, combine="min", after_round=None, wall="wall_s"):
    """Time chosen runs again in `rounds` rounds: each round, `select()` gives the
    (record, code) pairs to re-time, each once (then `after_round(i, times)` where
    given; `times`: record id -> its walls so far). ``combine="min"``: a record
    keeps the minimum of its times and counts the repeats; ``"median"``: its
    times become the medians over the rounds (its ok: ok in every round).
    `wall`: the record's key of the wall time (a study's own column name)."""
    times = {}
    for i in range(rounds):
        for r, code in select():
            out, w, c = clock(lambda: code.call(r["tol"]))
            if combine == "min":
                r[wall] = min(r[wall], w)
                r["cpu_s"] = min(r["cpu_s"], c)
                r["repeats"] += 1
            else:
                times.setdefault(id(r), (r, [], []))
                times[id(r)][1].append(w)
                times[id(r)][2].append(c)
                r["ok"] = r["ok"] and out["ok"]
        if after_round is not None:
            after_round(i, {key: w for key, (_, w, _) in times.items()})
    for r, w, c in times.values():
        r.update({wall: statistics.median(w), "cpu_s": statistics.median(c),
                  "repeats": rounds})  # fmt: skip


def in_loop_us(body, x0, const=None, n=200, rounds=5, stat=min):
    """Mean time (us) of one `body(x, const)` call inside one compiled loop of `n`
    calls (no dispatch cost), `stat` (min, median) of `rounds` loops after the
    compile. `const` (a scene, a matrix) is an argument of the compiled function,
    not a constant folded into it, as in the solver."""
    import equinox as eqx
    import jax

    @eqx.filter_jit
    def loop(x, c):
        return jax.lax.fori_loop(0, n, lambda i, x: body(x, c), x)

    block(loop(x0, const))
    times = [clock(lambda: block(loop(x0, const)))[1] for _ in range(rounds)]
    return stat(times) / n * 1e6


# ---------------------------------------------------------------------------
# The reference


def reference(case_or_scene, ts, method="cvode-numba", tol=REF_TOL, *, peer=None,
              rhs=None, max_steps=MAX_STEPS, verbose=False):  # fmt: skip
    """End-mass positions of a case at `ts` from a tight run, and its label.

    `method`: "cvode-numba" (CVODE BDF, band solver, on the case's numba peer,
    or `peer`, with its best Jacobian; an exception if it fails), a jaxstring
    solver name ("rodas5p", "kvaerno5"), or a callback peer of
    `jaxstring.testing.references` ("cvode-BDF", "scipy-Radau": JAX band
    Jacobian, on `rhs` where given; None where it fails).
    """
    import jaxstring

    case = case_or_scene if isinstance(case_or_scene, PendulumCase) else None
    scene = case.scene() if case is not None else case_or_scene
    if method == "cvode-numba":
        from jaxstring.testing import peers

        peer = peer or case.peer()
        y0 = np.ravel(np.asarray(scene.y0, dtype=np.float64))
        out = peers.cvode_solve(peer, ts, y0, tol, tol, jac=peer_jacobian(peer))
        if not out["ok"]:
            raise RuntimeError(f"reference failed: {out['message']}")
        return peer.end_mass(out["ys"]), f"CVODE-numba rtol=atol={tol:g}"
    if method in jaxstring.SOLVERS:
        traj, wall, _ = clock(lambda: jaxstring.simulate(
            scene, method, rtol=tol, atol=tol, ts=ts, max_steps=max_steps
        ))  # fmt: skip
        if verbose:
            print(
                f"{scene.name}: reference {method} {tol:g} in {wall:.1f}s "
                f"({int(traj.stats['num_accepted_steps'])} steps, {traj.status})"
            )
        return np.asarray(traj.end_mass), f"{method} at {tol:g}"
    from jaxstring.testing import references

    rhs = rhs or references.JaxRHS(scene)
    out = references.solve(rhs, method, ts, tol, tol, "jax-band")
    if not out["ok"]:
        return None, f"{method} at {tol:g} (failed)"
    return rhs.end_mass(out["ys"]), f"{method} at {tol:g}"
