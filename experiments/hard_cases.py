"""Hard cases as a matrix: which solver survives which stiff, slack or violent case.

Question: does every hard case end either in success or in a clear, documented
non-success status with finite data up to the failure -- never NaN before its
failure time, never an XLA error?

String pendulum (2 s): EA = 1e2 ... 1e9 N x alpha = 0, 0.01 s x formulation
(displacement; natural 2D; natural 3D with an out-of-plane angular velocity;
angle) x start (release at 90 deg; release from 135 deg with the slack law, which
snaps; swing: hanging in its static stretch with a rigid rotation omega =
sqrt(2 g / l); release from 170 deg) x solver (bdf, kvaerno5, rodas5p,
implicit_euler: adaptive at rtol = atol = 1e-6; theta: trapezoid, fixed step
dt = 0.005 s, the paper's) x k = 10, 40, 160.

Tether: the folded cable (`tether_fold`, interior angle 90-170 deg) with exact,
ACEAM and LMS tensions (dopri5, rodas5p, bdf); pay-out and haul-in at 2 m/s
(`tether_winch`, N = 41, 70 s; dopri5, bdf) in no current, the paper's 1 m/s and a
strong 3 m/s current; capped at 20000 steps. Tandem: fishtailing over
6 hours from 2.5 and 40 deg (the hawser goes slack and snaps taut), a 25 m/s wind
from 180 deg with no control, and law B's compensator in that wind and with its
surge force limited to 0.3 and 0.1 MN (saturated for the whole run).

Each case records status, accepted and rejected steps, wall and process CPU time
(compile apart: the first case of a compiled solve is preceded by a short
warm-up run, timed as `compile_s`), energy drift (alpha = 0), constraint error,
max strain, and whether any NaN or inf appears in the data before the failure
(`nan`: must never be True). Adaptive solves are capped at `--max-steps` so that
hopeless cases end quickly with a clear status.

Outcome classes: `success`; `fail:max_steps` (the cap reached while steps are
accepted: the step size is held down by accuracy -- first order for implicit
Euler, order reduction of the stiff axial modes); `fail:step_collapse` (the cap
reached with most attempted steps rejected: the step size collapsed); `fail:newton`
(the Newton iteration of a fixed step diverged); `fail:other` (another diffrax
status); `bad` (NaN before the failure, or an exception: must be 0).

Run: ``python experiments/hard_cases.py [--quick] [--k 10,40] [--families
pendulum,tether,tandem] [--formulations ...] [--solvers ...] [--starts ...]
[--EAs ...] [--max-steps 20000] [--report-only]``. Rows are appended to
results/hard_cases.csv as they finish; a rerun skips the cases already there, so a
long run can be split. The markdown table and the figure are rebuilt from the CSV.
"""

import os


# Equinox's runtime checks compile to host callbacks, which JAX's persistent cache
# does not store; as NaN they do not (jaxstring's command line does the same).
if __name__ == "__main__":  # as a script only: importing it changes nothing
    os.environ.setdefault("EQX_ON_ERROR", "nan")

import csv
import math

import _common as common
import equinox as eqx
import jax.numpy as jnp
import numpy as np
from scaling_k import swing_state

import jaxstring as js


NAME = "hard_cases"
EAS = (1e2, 1e4, 1e6, 1e8, 1e9)
ALPHAS = (0.0, 0.01)
FORMULATIONS = {  # name -> (formulation, dim)
    "displacement": ("displacement", 2),
    "natural2d": ("natural", 2),
    "natural3d": ("natural", 3),
    "angle": ("angle", 2),
}
STARTS = {  # name -> release angle from the downward vertical, rad
    "release90": math.pi / 2,
    "snap135": 3 * math.pi / 4,
    "swing": 0.0,
    "release170": math.radians(170.0),
}
SOLVERS = ("bdf", "kvaerno5", "rodas5p", "implicit_euler", "theta")
KS = (10, 40, 160)
T1 = 2.0
TOL = 1e-6
FIXED_DT = 0.005  # theta (trapezoid): the paper's step, 400 steps over 2 s
MAX_STEPS = 6_000  # string pendulum (k = 40, EA = 1e9, alpha = 0.01: BDF 5129 steps)
OTHER_MAX_STEPS = 20_000  # tether and tandem
# A "success" at alpha = 0 whose energy drifts by more than this share of
# (mu l + m_s) g l is listed as not conserving energy.
LOOSE_DRIFT = 0.1
N_SAVE = 201
G = 9.81
# Out-of-plane angular velocity of the natural 3D starts (rad/s): about x (the
# hanging string swings out of the plane) and about the vertical (a released
# string swings conically, as in tests/pendulum/test_physics.py).
OUT_OF_PLANE = (1.0, -2.0, 0.0)

COLUMNS = [
    "family",
    "k",
    "formulation",
    "start",
    "solver",
    "EA",
    "alpha",
    "outcome",
    "status",
    "steps",
    "rejected",
    "max_steps",
    "t_end",
    "compile_s",
    "wall_s",
    "cpu_s",
    "energy_drift",
    "constraint_error",
    "max_strain",
    "nan",
    "note",
]
KEY = ("family", "k", "formulation", "start", "solver", "EA", "alpha")


# --------------------------------------------------------------------------------------
# The string pendulum cases


def _cross(omega, v):
    """omega x v for (n, dim) vectors v, dim 2 (omega about z) or 3."""
    w = np.asarray(omega, float)
    if v.shape[1] == 2:
        return w[2] * np.stack([-v[:, 1], v[:, 0]], axis=1)
    return np.cross(w[None, :], v)


def start_state(model, formulation, start):
    """The initial state of a start: at rest and unstrained at its release angle,
    or (swing) hanging in its static stretch and rotating rigidly about the pivot at
    omega = sqrt(2 g / l); natural 3D adds `OUT_OF_PLANE`."""
    k, dim, l, EA = model.k, model.dim, float(model.l), float(model.EA)
    mu, m_s = float(model.mu), float(model.m_s)
    omega = np.zeros(3)
    if start == "swing":
        omega[2] = math.sqrt(2 * G / l)
    if dim == 3:
        omega += OUT_OF_PLANE
    y = np.array(model.initial_state(STARTS[start]))
    if formulation == "displacement":
        if start == "swing":
            y = swing_state(k, EA, l=l, mu=mu, m_s=m_s, g=G)
        y[:, dim:] = _cross(omega, y[:, :dim])
        return jnp.asarray(y)
    s = np.arange(k + 1) * l / k
    if start == "swing":  # hanging static strain T(s)/EA at the nodes
        y[:, 0] = G * (m_s + mu * (l - s)) / EA
    if formulation == "angle":
        y[:, 3] = omega[2]
    else:
        y[:, 1 + dim + 1 :] = _cross(omega, y[:, 1 : 1 + dim])
    return jnp.asarray(y)


def pendulum_scene(formulation, start, k, EA, alpha, t1):
    form, dim = FORMULATIONS[formulation]
    effects = ("gravity", "kelvin_voigt") + (("slack",) if start == "snap135" else ())
    scene = js.pendulum.string_pendulum(
        formulation=form, k=k, EA=EA, alpha=alpha, t1=t1, dim=dim, effects=effects
    )
    return eqx.tree_at(lambda s: s.y0, scene, start_state(scene.model, form, start))


def _valid(x, n):
    return np.asarray(x)[:n]


def pendulum_metrics(traj, scene):
    n = int(traj.n_valid)
    e = _valid(traj.energy, n)
    drift = float(np.max(np.abs(e - e[0])) / (2 * G)) if n else math.nan
    return dict(
        energy_drift=drift,
        constraint_error=float(np.max(_valid(traj.constraint_error, n), initial=0.0)),
        max_strain=float(np.max(np.abs(_valid(traj.strain, n)), initial=0.0)),
        note=f"strain {_range(_valid(traj.strain, n))}" if n else "no valid row",
    )


# --------------------------------------------------------------------------------------
# Outcome of one solve


def nan_before_failure(traj) -> bool:
    """NaN or inf in the state or any observable before the failure (after it the
    rows are NaN by design), or a success that does not reach the end."""
    n = int(traj.n_valid)
    ys = np.asarray(traj.ys)
    if traj.ok and n < ys.shape[0]:
        return True
    if not np.all(np.isfinite(ys[:n])):
        return True
    return any(not np.all(np.isfinite(np.asarray(v)[:n])) for v in traj.obs.values())


def outcome(traj, nan) -> str:
    if nan:
        return "bad"
    if traj.ok:
        return "success"
    code = int(traj.result)
    import diffrax as dfx

    if code == int(dfx.RESULTS.max_steps_reached._value):
        steps = int(traj.stats["num_steps"])
        rejected = int(traj.stats["num_rejected_steps"])
        return "fail:step_collapse" if rejected > 0.5 * steps else "fail:max_steps"
    if code == int(dfx.RESULTS.nonlinear_divergence._value):
        return "fail:newton"
    return "fail:other"


def _simulate_kw(solver, max_steps):
    kw = dict(rtol=TOL, atol=TOL, max_steps=max_steps)
    if not js.SOLVERS[solver][1]:
        kw["dt0"] = FIXED_DT
    return kw


def run_case(scene, solver, ts, metrics, max_steps, compile_s):
    """One timed solve of `scene` (already compiled); the row's outcome fields."""
    kw = _simulate_kw(solver, max_steps)

    def solve():
        try:
            return common.block(js.simulate(scene, solver, ts=ts, **kw)), None
        except Exception as e:  # noqa: BLE001  (an exception is a result: bad)
            return None, e

    (traj, e), wall, cpu = common.clock(solve)
    if e is not None:
        return dict(
            outcome="bad",
            status=f"{type(e).__name__}: {e}"[:200].replace("\n", " "),
            nan=False,
            compile_s=compile_s,
            wall_s=wall,
            cpu_s=cpu,
            max_steps=max_steps,
        )
    nan = nan_before_failure(traj)
    row = dict(
        outcome=outcome(traj, nan),
        status=traj.status.split(".")[0],
        steps=int(traj.stats["num_accepted_steps"]),
        rejected=int(traj.stats["num_rejected_steps"]),
        max_steps=max_steps if js.SOLVERS[solver][1] else "-",
        t_end=float(traj.t_end),
        compile_s=compile_s,
        wall_s=wall,
        cpu_s=cpu,
        nan=nan,
    )
    row.update(metrics(traj, scene))
    return row


def warm_up(scene, solver, max_steps, n_save=N_SAVE):
    """Compile `scene`'s solve (a 10 ms run: t1 is an array leaf, so the full run
    with `n_save` save times reuses the compiled solve); return its seconds."""
    t0 = float(scene.t0)
    short = eqx.tree_at(lambda s: s.t1, scene, jnp.asarray(t0 + 0.01))
    kw = _simulate_kw(solver, max_steps)
    ts = jnp.linspace(t0, t0 + 0.01, n_save)

    def solve():
        try:
            common.block(js.simulate(short, solver, ts=ts, **kw))
        except Exception:  # noqa: BLE001  (the full run reports it)
            pass

    return common.clock(solve)[1]


# --------------------------------------------------------------------------------------
# Tether and tandem cases


def _range(x):
    return f"{float(np.min(x)):.4g} to {float(np.max(x)):.4g}"


def tether_metrics(traj, scene):
    n = int(traj.n_valid)
    force = np.concatenate(
        [_valid(traj.root_force, n), _valid(traj.fast_force, n)], axis=1
    )
    fmax = float(np.max(np.abs(force), initial=0.0))
    return dict(
        constraint_error=float(np.max(np.abs(_valid(traj.length_error, n)), initial=0)),
        max_strain=float(np.max(_valid(traj.constraint_error, n), initial=0.0)),
        note=f"max end force component {fmax:.4g} N",
    )


def tandem_metrics(traj, scene):
    n = int(traj.n_valid)
    tension = _valid(traj.tension, n)
    span = _valid(traj.span, n)
    l0 = 80.0
    ctl = _valid(traj.control, n)
    note = (
        f"tension {_range(tension / 1e3)} kN, span {_range(span)} m"
        if n
        else "no valid row"
    )
    if np.any(ctl):
        note += f", |X| max {float(np.max(np.abs(ctl[:, 0]))) / 1e3:.4g} kN"
    return dict(
        max_strain=float(np.max((span - l0) / l0, initial=0.0)),
        note=note,
    )


def tether_cases(quick):
    """(key fields, scene, solvers, metrics, compile group) of the tether cases."""
    t = js.tether
    angles = (90.0, 130.0, 170.0) if quick else (90.0, 110.0, 130.0, 150.0, 170.0)
    methods = ("exact", "aceam", "lms")
    solvers = ("dopri5", "rodas5p", "bdf")
    for method in methods:
        for angle in angles:
            sc = t.tether_fold(method=method, interior_deg=angle, t1=1.0)
            yield (
                dict(formulation=f"fold/{method}", start=f"{angle:g} deg"),
                sc,
                solvers,
                ("fold", method),
            )
    N = 21 if quick else 41
    for method in ("exact", "aceam"):
        for current in (0.0, 1.0, 3.0):
            sc = t.tether_winch(
                method=method,
                haul_speed=2.0,
                payout_speed=2.0,
                N=N,
                current=(-current, 0.0, 0.0),
            )
            yield (
                dict(formulation=f"winch 2 m/s/{method}", start=f"current {current:g}"),
                sc,
                ("dopri5", "bdf"),
                ("winch", method),
            )


def tandem_cases(quick):
    td = js.tandem
    t1 = 3600.0 if quick else 21600.0
    solvers = ("tsit5", "kvaerno5", "rodas5p", "bdf")
    for pert in (2.5, 40.0):
        sc = td.tandem_fishtail(perturbation_deg=pert, t1=t1)
        yield (
            dict(formulation="fishtail 6 h", start=f"{pert:g} deg"),
            sc,
            solvers,
            ("fishtail",),
        )
    sc = td.tandem_equilibria(V_w=25.0, Delta_w_deg=180.0, t1=t1)
    yield (
        dict(formulation="wind 25 m/s 180 deg", start="no control"),
        sc,
        solvers,
        ("wind",),
    )
    base = td.tandem_controlled(env="wind15_180", law="B", t1=4000.0)
    wind = [i for i, e in enumerate(base.effects) if type(e).__name__ == "OCIMFWind"][0]
    base = eqx.tree_at(lambda s: s.effects[wind].speed, base, jnp.asarray(25.0))
    ctl = [i for i, e in enumerate(base.effects) if hasattr(e, "X_max")][0]
    for X_max in (1.5e6, 3e5, 1e5):
        sc = eqx.tree_at(
            lambda s: s.effects[ctl].X_max, base, jnp.asarray(X_max, float)
        )
        yield (
            dict(
                formulation="controlled B, wind 25 m/s 180 deg",
                start=f"X_max {X_max / 1e6:g} MN",
            ),
            sc,
            ("tsit5", "kvaerno5", "rodas5p", "bdf"),
            ("controlled",),
        )


# --------------------------------------------------------------------------------------
# Resumable CSV


def _cell(value):
    """A key column's text: numbers in the shortest form (`1e+06`)."""
    return f"{value:g}" if isinstance(value, float) else value


def _key(row):
    return tuple(str(row.get(c, "")) for c in KEY)


def read_rows(path):
    if not path.exists():
        return []
    with open(path) as f:
        lines = [ln for ln in f if not ln.startswith("#")]
    return list(csv.DictReader(lines))


def stamps(path):
    if not path.exists():
        return []
    with open(path) as f:
        return [ln[2:].strip() for ln in f if ln.startswith("# run: ")]


class Appender:
    """Appends rows to the CSV as they finish (header and a stamp line first)."""

    def __init__(self, path):
        self.path = path
        new = not path.exists()
        self.f = open(path, "a", newline="")
        if new:
            self.f.write(f"# Hard cases ({NAME})\n")
        self.f.write(f"# run: {common.stamp_line(f'{NAME}.csv')}\n")
        self.w = csv.DictWriter(self.f, fieldnames=COLUMNS, extrasaction="ignore")
        if new:
            self.w.writeheader()
        self.f.flush()

    def add(self, row):
        out = {}
        for c in COLUMNS:
            v = row.get(c, "")
            out[c] = f"{v:.4g}" if isinstance(v, float) else v
        self.w.writerow(out)
        self.f.flush()


# --------------------------------------------------------------------------------------
# Driver


def _announce(row):
    print(
        f"{row['family']:8s} k={row['k']} {row['formulation']:22s} {row['start']:12s} "
        f"{row['solver']:14s} EA={row['EA']} a={row['alpha']} -> {row['outcome']:18s}"
        f" steps={row.get('steps')} rej={row.get('rejected')} "
        f"wall={common.fmt(row.get('wall_s'))} nan={row.get('nan')}",
        flush=True,
    )


def run_pendulum(appender, done, ks, formulations, starts, solvers, EAs, t1, max_steps):
    ts = jnp.linspace(0.0, t1, N_SAVE)
    for k in ks:
        for form in formulations:
            for solver in solvers:
                for start in starts:
                    compiled = None
                    for EA in EAs:
                        for alpha in ALPHAS:
                            case = ("pendulum", k, form, start, solver, EA, alpha)
                            key = dict(zip(KEY, map(_cell, case)))
                            if _key(key) in done:
                                continue
                            sc = pendulum_scene(form, start, k, EA, alpha, t1)
                            if compiled is None:
                                compiled = warm_up(sc, solver, max_steps)
                                comp = compiled
                            else:
                                comp = 0.0
                            row = dict(key)
                            row.update(
                                run_case(
                                    sc, solver, ts, pendulum_metrics, max_steps, comp
                                )
                            )
                            appender.add(row)
                            _announce(row)


def run_family(appender, done, family, cases, metrics, max_steps, n_save=401):
    warmed = set()
    for fields, sc, solvers, group in cases:
        ts = jnp.linspace(float(sc.t0), float(sc.t1), n_save)
        for solver in solvers:
            key = dict(family=family, k="-", solver=solver, EA="-", alpha="-")
            key.update(fields)
            if _key(key) in done:
                continue
            comp = 0.0
            if (group, solver) not in warmed:
                comp = warm_up(sc, solver, max_steps, n_save)
                warmed.add((group, solver))
            row = dict(key)
            row.update(run_case(sc, solver, ts, metrics, max_steps, comp))
            appender.add(row)
            _announce(row)


# --------------------------------------------------------------------------------------
# Report


OUTCOMES = (
    "success",
    "fail:max_steps",
    "fail:step_collapse",
    "fail:newton",
    "fail:other",
    "bad",
)
COLOURS = ("#2ca02c", "#ff7f0e", "#9467bd", "#d62728", "#8c564b", "#000000")
REASONS = {
    "fail:max_steps": "the step cap reached while steps are accepted: the step size "
    "is held down by accuracy -- mostly undamped (alpha = 0) strings at EA >= 1e4, "
    "whose axial vibration rtol = 1e-6 asks to follow; adaptive implicit Euler "
    "everywhere (first order: the order barrier); Rodas5P at EA >= 1e8 (order "
    "reduction on the stiff axial modes)",
    "fail:step_collapse": "the step cap reached with most attempted steps "
    "rejected: the step size collapsed (at the snaps of the slack law; tether: at "
    "the winch schedule's corners)",
    "fail:newton": "the Newton iteration of a fixed step diverged (the trapezoid at "
    "dt = 0.005 s: no shorter step to fall back to)",
    "fail:other": "another diffrax status (see `status`)",
}


def counts(rows):
    c = {o: 0 for o in OUTCOMES}
    for r in rows:
        c[r["outcome"]] = c.get(r["outcome"], 0) + 1
    return c


def _summary_table(rows, by):
    keys = sorted({tuple(r[b] for b in by) for r in rows}, key=str)
    lines = [
        "| " + " | ".join(by) + " | cases | " + " | ".join(OUTCOMES) + " |",
        "|" + "---|" * (len(by) + 1 + len(OUTCOMES)),
    ]
    for kk in keys:
        sub = [r for r in rows if tuple(r[b] for b in by) == kk]
        c = counts(sub)
        lines.append(
            "| "
            + " | ".join(kk)
            + f" | {len(sub)} | "
            + " | ".join(str(c[o]) for o in OUTCOMES)
            + " |"
        )
    return lines


def _f(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def report(path, max_steps):
    rows = read_rows(path)
    if not rows:
        print("no rows")
        return None
    c = counts(rows)
    fails = sum(c[o] for o in OUTCOMES if o.startswith("fail"))
    pend = [r for r in rows if r["family"] == "pendulum"]
    lines = [
        "# Hard cases: which solver survives which case",
        "",
        common.stamp_markdown(),
        "",
        "Runs that wrote the rows (appended, resumable):",
        "",
    ]
    lines += [f"- {s}" for s in stamps(path)]
    lines += [
        "",
        f"**{len(rows)} cases: {c['success']} succeeded, {fails} clear failures, "
        f"{c['bad']} bad** (NaN before the failure or an exception; must be 0).",
        "",
        f"Settings: adaptive solvers at rtol = atol = {TOL:g}, capped at max_steps "
        f"(per row in the CSV: {', '.join(sorted({r['max_steps'] for r in rows}))}; "
        "a cap, so that hopeless cases end early with a clear status); theta "
        f"(trapezoid) with a fixed step dt = {FIXED_DT} s; string pendulum t1 = "
        f"{T1:g} s, {N_SAVE} saved points; `compile_s` is the warm-up of the first "
        "case of each compiled solve (0: reused); wall and CPU (this process, all "
        "threads) are one run each, on a shared machine: CPU is the steadier. "
        "`energy_drift` is max |E - E0| / ((mu l + m_s) g l) up to the failure (a "
        "drift at alpha = 0; the dissipated share at alpha = 0.01). "
        "`constraint_error`: max | |t| - 1 | for the natural variables (0 where the "
        "formulation has no constraint); the tether's max |length error|. "
        "`max_strain`: max |eps| (tether: max link strain; tandem: hawser "
        "(span - l0)/l0).",
        "",
        "Outcomes:",
        "",
    ]
    lines += [f"- `{o}`: {REASONS[o]}" for o in REASONS]
    lines += ["", "## By family, k and solver", ""]
    lines += _summary_table(rows, ("family", "k", "solver"))
    if pend:
        lines += ["", "## String pendulum by formulation and start", ""]
        lines += _summary_table(pend, ("formulation", "start"))
        lines += ["", "## String pendulum by EA", ""]
        lines += _summary_table(pend, ("EA", "solver"))

        def drifts(solvers):
            return [
                _f(r["energy_drift"])
                for r in pend
                if r["outcome"] == "success"
                and r["alpha"] == "0"
                and r["solver"] in solvers
            ]

        cons = [
            _f(r["constraint_error"]) for r in pend if r["formulation"] == "natural2d"
        ]
        cons3 = [
            _f(r["constraint_error"]) for r in pend if r["formulation"] == "natural3d"
        ]
        adaptive = [s for s in SOLVERS if js.SOLVERS[s][1]]
        for label, ds in (
            ("adaptive solvers", drifts(adaptive)),
            ("theta (fixed step)", drifts(("theta",))),
        ):
            if ds:
                lines += [
                    "",
                    f"Successful alpha = 0 runs, {label}: energy drift max |E - E0| "
                    f"/ ((mu l + m_s) g l) median {np.nanmedian(ds):.2e}, max "
                    f"{np.nanmax(ds):.2e} ({len(ds)} runs).",
                ]
        lines += [
            "",
            "Constraint error max | |t| - 1 | (natural 2D / 3D, every case, up to "
            f"the failure): {np.nanmax(cons, initial=0):.1e} / "
            f"{np.nanmax(cons3, initial=0):.1e}.",
        ]
    loose = [
        r
        for r in pend
        if r["outcome"] == "success"
        and r["alpha"] == "0"
        and _f(r["energy_drift"]) > LOOSE_DRIFT
    ]
    if loose:
        lines += [
            "",
            f"## Successes that do not conserve energy (alpha = 0, drift > "
            f"{LOOSE_DRIFT:g})",
            "",
            "Finite and successful, but not accurate: a fixed step has no error "
            "control.",
            "",
        ]
        lines += [
            f"- k = {r['k']}, {r['formulation']}, {r['start']}, {r['solver']}, EA = "
            f"{r['EA']}: drift {r['energy_drift']}, max strain {r['max_strain']}"
            for r in loose
        ]
    bad = [r for r in rows if r["outcome"] == "bad"]
    if bad:
        lines += ["", "## Bad cases", ""]
        lines += [
            f"- {', '.join(f'{c}={r[c]}' for c in KEY)}: {r['status']}" for r in bad
        ]
    others = [r for r in rows if r["family"] != "pendulum"]
    if others:
        cols = [
            "family",
            "formulation",
            "start",
            "solver",
            "outcome",
            "steps",
            "rejected",
            "t_end",
            "compile_s",
            "wall_s",
            "cpu_s",
            "constraint_error",
            "max_strain",
            "nan",
            "note",
        ]
        lines += ["", "## Tether and tandem cases", ""]
        lines += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        for r in others:
            lines.append("| " + " | ".join(str(r.get(c, "")) for c in cols) + " |")
    lines += [
        "",
        f"Every case, one row each: `{NAME}.csv` (columns {', '.join(COLUMNS)}).",
        "",
    ]
    text = "\n".join(lines)
    common.write_text(f"{NAME}.md", text)
    print(text)
    figure(rows)
    return c


def figure(rows):
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    pend = [r for r in rows if r["family"] == "pendulum"]
    ks = sorted({int(r["k"]) for r in pend})
    other = [r for r in rows if r["family"] != "pendulum"]
    panels = len(ks) + (1 if other else 0)
    fig, axes = common.new_figure(1, max(panels, 1), w=13.0, h=5.5)
    cmap = ListedColormap(COLOURS)
    code = {o: i for i, o in enumerate(OUTCOMES)}
    ylabels = [f"{f} / {s}" for f in FORMULATIONS for s in STARTS]
    xlabels = [f"{s} {EA:.0e} {a:g}" for s in SOLVERS for EA in EAS for a in ALPHAS]
    for ax, k in zip(axes[:, 0], ks):
        grid = np.full((len(ylabels), len(xlabels)), np.nan)
        for r in pend:
            if int(r["k"]) != k:
                continue
            y = ylabels.index(f"{r['formulation']} / {r['start']}")
            x = xlabels.index(
                f"{r['solver']} {float(r['EA']):.0e} {float(r['alpha']):g}"
            )
            grid[y, x] = code[r["outcome"]]
        ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(OUTCOMES) - 0.5, aspect="auto")
        ax.set_yticks(range(len(ylabels)), ylabels, fontsize=7)
        per = len(EAS) * len(ALPHAS)
        ax.set_xticks(
            [i * per + per / 2 - 0.5 for i in range(len(SOLVERS))], SOLVERS, fontsize=8
        )
        for i in range(1, len(SOLVERS)):
            ax.axvline(i * per - 0.5, color="w", lw=2)
        for i in range(1, len(FORMULATIONS)):
            ax.axhline(i * len(STARTS) - 0.5, color="w", lw=2)
        ax.set_title(
            f"string pendulum, k = {k}: per solver EA 1e2 ... 1e9 x alpha 0, 0.01 "
            "(white: not run)",
            fontsize=9,
        )
    if other:
        ax = axes[len(ks), 0] if len(ks) < panels else axes[-1, 0]
        cases = sorted({(r["family"], r["formulation"], r["start"]) for r in other})
        solvers = sorted({r["solver"] for r in other})
        grid = np.full((len(cases), len(solvers)), np.nan)
        for r in other:
            y = cases.index((r["family"], r["formulation"], r["start"]))
            grid[y, solvers.index(r["solver"])] = code[r["outcome"]]
        ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(OUTCOMES) - 0.5, aspect="auto")
        ax.set_yticks(
            range(len(cases)), [f"{b} / {c}" for _, b, c in cases], fontsize=7
        )
        ax.set_xticks(range(len(solvers)), solvers, fontsize=8)
        ax.set_title("tether and tandem", fontsize=9)
    fig.legend(
        handles=[Patch(color=c, label=o) for o, c in zip(OUTCOMES, COLOURS)],
        loc="lower center",
        ncol=len(OUTCOMES),
    )
    fig.subplots_adjust(bottom=0.7 / fig.get_figheight())
    common.savefig(fig, NAME)


def main(
    quick=False,
    k=None,
    families=None,
    formulations=None,
    starts=None,
    solvers=None,
    EAs=None,
    max_steps=MAX_STEPS,
    report_only=False,
):
    common.set_quick(quick)
    js.enable_compilation_cache()
    path = common.results_dir() / f"{NAME}.csv"
    if not report_only:
        done = {_key(r) for r in read_rows(path)}
        appender = Appender(path)
        families = families or ["pendulum", "tether", "tandem"]
        t1 = 0.2 if quick else T1
        if "pendulum" in families:
            run_pendulum(
                appender,
                done,
                k or ((10,) if quick else (10, 40)),
                formulations or list(FORMULATIONS),
                starts or list(STARTS),
                solvers or list(SOLVERS),
                EAs or ((1e2, 1e9) if quick else EAS),
                t1,
                max_steps,
            )
        if "tether" in families:
            run_family(
                appender,
                done,
                "tether",
                tether_cases(quick),
                tether_metrics,
                OTHER_MAX_STEPS,
            )
        if "tandem" in families:
            run_family(
                appender,
                done,
                "tandem",
                tandem_cases(quick),
                tandem_metrics,
                OTHER_MAX_STEPS,
            )
    return report(path, max_steps)


if __name__ == "__main__":
    common.run_study(
        main,
        lists={
            "k": int,
            "families": str,
            "formulations": str,
            "starts": str,
            "solvers": str,
            "EAs": float,
        },
        max_steps=dict(default=MAX_STEPS, type=int, flag="max-steps"),
        report_only=dict(action="store_true", flag="report-only"),
    )
