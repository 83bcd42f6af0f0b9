"""Fig 9 of Poth et al.: run time vs EA for the three formulations, against CVODE.

Question: which set of variables -- displacement, natural (eps, t) or natural
(eps, phi) -- is cheapest to integrate as the string gets stiffer (EA = 1e4 ... 1e9),
with jaxstring's BDF, Kvaerno5 (the ESDIRK method of the paper's gap) and Rodas5P,
and how far is each from CVODE as an expert sets it up? The peer is
jaxstring/testing/peers.py: the same equations in numba, CVODE BDF with the band linear
solver and the analytic banded Jacobian (displacement variables) or CVODE's banded
difference quotients (natural variables). IDA driving jaxstring's own JAX functions
through Python callbacks (jaxstring/testing/references.py, band Jacobian from JAX) is a
second, labelled row (``--no_callback`` leaves it out).

Settings: the paper's pendulum, k = 40, alpha = 0.01 s, released horizontal, 2 s,
rtol = atol = 1e-7 for every code. Error: the largest end-mass distance at 41 save
times from CVODE-numba at rtol = atol = 1e-11 in the same variables. Times: wall and
process CPU (all threads) of each run, the median over ``--repeats`` interleaved
rounds (every code of a scene once per round) after a first, untimed call per code;
compile time (jaxstring's first call minus the median, numba's compile or cache
load, JAX's jit of the callback functions) is reported apart. Normalised like the
paper: 1 = the fastest best-solver run at EA = 1e4; and each run as a ratio to
CVODE-numba at the same formulation and EA.

Run: ``python experiments/fig9_formulations.py [--quick] [--solvers a,b]``.
"""

import math
import os

import _common as common
import harness
import numpy as np

import jaxstring


FORMULATIONS = ("displacement", "natural", "angle")
EAS = (1e4, 1e5, 1e6, 1e7, 1e8, 1e9)
SOLVERS = ("bdf", "kvaerno5", "rodas5p")
LABEL = {"displacement": "displacement", "natural": "(eps, t)", "angle": "(eps, phi)"}
CVODE = "CVODE-numba"
CALLBACK = "IDA on JAX callbacks"
REF_TOL = harness.REF_TOL


def _codes(scene, peer, ts, names, callback):
    """CVODE-numba, the jaxstring solvers `names` and (where `callback`) IDA on
    jaxstring's JAX functions through callbacks, on one scene."""
    y0 = np.ravel(np.asarray(scene.y0, dtype=np.float64))
    codes = [harness.cvode_numba_code(peer, ts, y0)]
    codes += [harness.jaxstring_code(scene, n, ts) for n in names]
    if callback:
        codes.append(harness.callback_code(
            scene, "ida", ts, label=f"{CALLBACK} [band Jacobian]", max_fev=2_000_000
        ))  # fmt: skip
    return codes


def main(
    quick=False,
    formulations=None,
    EAs=None,
    solvers=None,
    repeats=None,
    tol=1e-7,
    budget_s=60.0,
    no_callback=False,
):
    """Run the Fig 9 study; return the rows (one per formulation, EA and code)."""
    common.set_quick(quick)
    k = 8 if quick else 40
    t1 = 0.2 if quick else 2.0
    formulations = formulations or (
        ("displacement", "angle") if quick else FORMULATIONS
    )
    EAs = EAs or ((1e4, 1e6) if quick else EAS)
    repeats = repeats or (1 if quick else 5)
    names = solvers or (["kvaerno5"] if quick else list(SOLVERS))
    names = [n for n in names if n in jaxstring.SOLVERS and jaxstring.SOLVERS[n][1]]
    ts = np.linspace(0.0, t1, 41)
    rows, ref_checks = [], []
    callback_dead = set()
    for form in formulations:
        dead = set()
        for EA in EAs:
            case = harness.PendulumCase(form, EA=EA, k=k, t1=t1)
            scene, peer = case.scene(), case.peer()
            peer.warmup()
            ref, _ = harness.reference(case, ts, "cvode-numba", REF_TOL, peer=peer)
            # The reference's own accuracy: its distance from a 10x looser run.
            loose, _ = harness.reference(case, ts, "cvode-numba", 10 * REF_TOL,
                                         peer=peer)  # fmt: skip
            ref_diff = common.end_mass_error(loose, ref)
            ref_checks.append(ref_diff)
            live = [n for n in names if n not in dead]
            callback = not no_callback and form not in callback_dead
            codes = _codes(scene, peer, ts, live, callback)
            load = os.getloadavg()[0]
            # every code once per round (medians), compile apart
            records = harness.score(harness.interleaved(codes, tol, repeats), ref)
            for code, r in zip(codes, harness.rows(records, {"code": "solver"})):
                r.update(formulation=form, EA=EA, ref_diff_m=ref_diff, load_1min=load)
                # A code that failed or ran past the budget sits out the stiffer EAs.
                if not r["ok"] or r["cpu_s"] > budget_s:
                    if code.kind == "jaxstring":
                        dead.add(code.label)
                    elif code.kind == "callback":
                        callback_dead.add(form)
                rows.append(r)
                print(
                    f"{form} EA={EA:g} {code.label:40s} ok={r['ok']} "
                    f"wall={r['wall_s']:.3f}s cpu={r['cpu_s']:.3f}s "
                    f"err={r['err_m']:.2e} attempted={r.get('attempted', '-')}",
                    flush=True,
                )
    best = _best(rows, formulations, names, EAs)
    _normalise(rows, best, EAs)
    tag = "_quick" if quick else ""
    common.write_table(
        f"fig9_formulations{tag}",
        rows,
        (
            "formulation EA solver best ok wall_s cpu_s repeats compile_s rel_cpu "
            "rel_wall x_cvode_cpu x_cvode_wall err_m attempted accepted rejected "
            "nfev ref_diff_m load_1min status"
        ).split(),
        f"Fig 9: run time vs EA per formulation, k={k}, t1={t1:g} s, rtol=atol={tol:g}",
        notes=[
            *summary(rows, formulations, names, EAs, best),
            "best: the jaxstring solver with the smallest total CPU time over the "
            "EAs for that formulation; rel_cpu, rel_wall = time / the fastest "
            "best-solver run at the smallest EA (the paper's normalisation); "
            f"x_cvode_cpu, x_cvode_wall = time / {CVODE}'s at the same formulation "
            "and EA, measured in the same interleaved rounds.",
            f"{CVODE}: CVODE BDF (scikit-sundae) with the band linear solver on the "
            "numba right-hand side of jaxstring/testing/peers.py; analytic banded "
            "Jacobian in displacement variables, CVODE's banded difference "
            "quotients in natural variables. "
            + (
                "The callback IDA row was left out (--no_callback)."
                if no_callback
                else f"{CALLBACK}: IDA with the band Jacobian from JAX, jaxstring's "
                "vector field through Python callbacks "
                "(jaxstring/testing/references.py)."
            ),
            f"err_m: largest end-mass distance at the {len(ts)} save times from "
            f"{CVODE} at rtol = atol = {REF_TOL:g} in the same variables; "
            f"ref_diff_m: that reference's distance from its own run at "
            f"{10 * REF_TOL:g} ({common.fmt(min(ref_checks))} to "
            f"{common.fmt(max(ref_checks))} m).",
            f"wall_s, cpu_s: medians over {repeats} interleaved rounds after a first "
            "untimed call per code (a run over "
            f"{common.LONG_RUN_S:g} s is timed once); CPU = process CPU, all threads. "
            "compile_s: jaxstring's first call minus the median; the peers' numba "
            "compile or cache load and JAX jit. attempted = accepted + rejected "
            "steps (jaxstring); nfev: right-hand-side calls (peers). load_1min: "
            "load at the start of the scene.",
        ],
    )
    _plot(rows, formulations, best, k, tol, tag)
    return rows


def _best(rows, formulations, names, EAs):
    """Per formulation, the jaxstring solver with the least total CPU time over the
    EAs where it ran everywhere (else the one that got furthest)."""
    best = {}
    for form in formulations:
        totals, counts = {}, {}
        for name in names:
            rs = [r for r in rows if r["formulation"] == form and r["solver"] == name]
            counts[name] = sum(r["ok"] for r in rs)
            if len(rs) == len(EAs) and all(r["ok"] for r in rs):
                totals[name] = sum(r["cpu_s"] for r in rs)
        if totals:
            best[form] = min(totals, key=totals.get)
        elif counts:
            best[form] = max(counts, key=counts.get)
    return best


def _normalise(rows, best, EAs):
    for field, rel in (("cpu_s", "rel_cpu"), ("wall_s", "rel_wall")):
        base = min(
            (
                r[field]
                for r in rows
                if r["ok"] and r["EA"] == EAs[0] and r["solver"] == best.get(
                    r["formulation"])
            ),
            default=math.nan,
        )  # fmt: skip
        for r in rows:
            r[rel] = r[field] / base if r["ok"] else math.nan
    for r in rows:
        r["best"] = r["solver"] == best.get(r["formulation"])
        cv = _row(rows, r["formulation"], r["EA"], CVODE)
        for field, x in (("cpu_s", "x_cvode_cpu"), ("wall_s", "x_cvode_wall")):
            ok = cv is not None and cv["ok"] and r["ok"]
            r[x] = r[field] / cv[field] if ok else math.nan


def _row(rows, form, EA, who):
    """The row of code `who` (a jaxstring name or a label's start) at (form, EA)."""
    for r in rows:
        if (
            r["formulation"] == form
            and r["EA"] == EA
            and (r["solver"] == who or r["solver"].startswith(who + " ["))
        ):
            return r
    return None


def summary(rows, formulations, names, EAs, best):
    """One note per formulation: CPU time at the smallest and largest EA and its
    growth for each code, the range of the ratio to CVODE-numba, the errors."""
    lo, hi = EAs[0], EAs[-1]
    out = []
    for form in formulations:
        parts = []
        first = [best[form]] if form in best else []
        for who in first + [n for n in names if n not in first] + [CVODE, CALLBACK]:
            a, b = _row(rows, form, lo, who), _row(rows, form, hi, who)
            if a is None:
                continue
            sel = [
                r
                for r in rows
                if r["formulation"] == form
                and (r["solver"] == who or r["solver"].startswith(who + " ["))
            ]
            okr = [r for r in sel if r["ok"]]
            text = f"{who}{' (best)' if who == best.get(form) else ''}: "
            if b is not None and a["ok"] and b["ok"]:
                text += (
                    f"{a['cpu_s']:.3g} -> {b['cpu_s']:.3g} s CPU "
                    f"({b['cpu_s'] / a['cpu_s']:.2g}x)"
                )
            else:
                text += f"{sum(r['ok'] for r in sel)} of {len(EAs)} EAs ran"
            if who != CVODE and okr:
                xs = [r["x_cvode_cpu"] for r in okr]
                text += f", {min(xs):.2g}-{max(xs):.2g}x {CVODE}'s CPU"
            if okr:
                errs = [r["err_m"] for r in okr]
                text += f", error {min(errs):.1e}-{max(errs):.1e} m"
            parts.append(text)
        out.append(f"{LABEL[form]}, EA {lo:.0e} -> {hi:.0e}: " + "; ".join(parts) + ".")
    return out


def _plot(rows, formulations, best, k, tol, tag):
    fig, axes = common.new_figure(2, 1, w=5.2)
    for ax, rel, what in (
        (axes[0][0], "rel_cpu", "CPU time"),
        (axes[0][1], "rel_wall", "wall time"),
    ):
        for i, form in enumerate(formulations):
            who = [(best[form], "-", f"{best[form]} (best)")] if form in best else []
            if best.get(form) != "kvaerno5":
                who.append(("kvaerno5", ":", "kvaerno5"))
            who.append((CVODE, "--", CVODE))
            for name, style, label in who:
                pts = [
                    (r["EA"], r[rel])
                    for r in rows
                    if r["formulation"] == form
                    and r["ok"]
                    and (r["solver"] == name or r["solver"].startswith(f"{name} ["))
                ]
                if pts:
                    x, y = zip(*pts)
                    ax.loglog(
                        x, y, style, color=f"C{i}", marker="o", ms=3,
                        label=f"{LABEL[form]}: {label}",
                    )  # fmt: skip
        ax.set_xlabel("EA (N)")
        ax.set_ylabel(f"{what} (1 = fastest best solver at the smallest EA)")
        ax.set_title(f"Fig 9: {what}, k={k}, rtol={tol:g}", fontsize=9)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.tight_layout()
    fig.legend(handles, labels, loc="upper center", fontsize=7, ncol=3,
               bbox_to_anchor=(0.5, 0.0))  # fmt: skip
    common.savefig(fig, f"fig9_formulations{tag}")


if __name__ == "__main__":
    common.run_study(
        main,
        lists={"formulations": str, "EAs": float, "solvers": str},
        no_callback=dict(action="store_true", help=f"leave out {CALLBACK}"),
    )
