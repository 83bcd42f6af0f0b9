"""Fig 9 of Poth et al.: wall time vs EA for the three formulations.

Question: which set of variables -- displacement, natural (eps, t) or natural
(eps, phi) -- is cheapest to integrate as the string gets stiffer (EA = 1e4 ... 1e9),
each with its best jaxstring solver (and with IDA, the descendant of the paper's
DASSL, on the identical right-hand side)? Normalised like the paper: 1 = the
fastest run at EA = 1e4. Settings: k = 40, 2 s, rtol = atol = 1e-7.

Run: ``python experiments/fig9_formulations.py [--quick]``.
"""

import math

import _common as common
import numpy as np
import references
from fig10_integrators import tight_reference

import jaxstring


FORMULATIONS = ("displacement", "natural", "angle")
EAS = (1e4, 1e5, 1e6, 1e7, 1e8, 1e9)
LABEL = {"displacement": "displacement", "natural": "(eps, t)", "angle": "(eps, phi)"}


def main(
    quick=False,
    formulations=None,
    EAs=None,
    solvers=None,
    repeats=None,
    tol=1e-7,
    budget_s=120.0,
):
    """Run the Fig 9 study; return the rows (one per formulation, EA, solver)."""
    common.set_quick(quick)
    k = 8 if quick else 40
    t1 = 0.2 if quick else 2.0
    formulations = formulations or (
        ("displacement", "angle") if quick else FORMULATIONS
    )
    EAs = EAs or ((1e4, 1e6) if quick else EAS)
    repeats = repeats or (1 if quick else 3)
    names = solvers or (["kvaerno5"] if quick else common.solver_names("implicit"))
    names = [n for n in names if n in jaxstring.SOLVERS and jaxstring.SOLVERS[n][1]]
    avail = references.available()
    peer = "ida" if avail["ida"] else ("cvode-BDF" if avail["cvode-BDF"] else None)
    ts = np.linspace(0.0, t1, 41)
    rows = []
    for form in formulations:
        dead = set()
        for EA in EAs:
            scene = jaxstring.scenes.string_pendulum(
                formulation=form, k=k, EA=EA, t1=t1
            )
            ref, ref_label = tight_reference(scene, ts, 1e-8 if quick else 1e-10)
            for name in names:
                if name in dead:
                    continue
                r = common.run_jaxstring(
                    scene, name, ts, rtol=tol, atol=tol, repeats=repeats
                )
                end = r.pop("end")
                r.update(
                    formulation=form,
                    EA=EA,
                    err_m=common.end_mass_error(end, ref) if r["ok"] else math.nan,
                )
                if not r["ok"] or r["run_s"] > budget_s:
                    dead.add(name)
                rows.append(r)
                print(f"{form} EA={EA:g} {name}: {r['run_s']:.3g} s", flush=True)
            if peer is not None:
                rhs = references.JaxRHS(scene)
                r = common.run_peer(
                    rhs, peer, "jax-band", ts, rtol=tol, atol=tol, repeats=repeats
                )
                end = r.pop("end")
                r.update(
                    formulation=form,
                    EA=EA,
                    err_m=common.end_mass_error(end, ref) if r["ok"] else math.nan,
                )
                rows.append(r)
    # Best jaxstring solver per formulation: smallest summed time over the EAs
    # where every candidate ran (a solver that failed somewhere is not "best").
    best = {}
    for form in formulations:
        totals = {}
        for name in names:
            rs = [r for r in rows if r["formulation"] == form and r["solver"] == name]
            if len(rs) == len(EAs) and all(r["ok"] for r in rs):
                totals[name] = sum(r["run_s"] for r in rs)
        if totals:
            best[form] = min(totals, key=totals.get)
        else:  # none ran everywhere: the one that got furthest
            counts = {
                n: sum(
                    r["ok"]
                    for r in rows
                    if r["formulation"] == form and r["solver"] == n
                )
                for n in names
            }
            best[form] = max(counts, key=counts.get)
    base = min(
        (
            r["run_s"]
            for r in rows
            if r["ok"] and r["EA"] == EAs[0] and r["solver"] == best[r["formulation"]]
        ),
        default=math.nan,
    )
    for r in rows:
        r["cpu_rel"] = r["run_s"] / base if r["ok"] else math.nan
        r["best"] = r["solver"] == best.get(r["formulation"])
    tag = "_quick" if quick else ""
    common.write_table(
        f"fig9_formulations{tag}",
        rows,
        (
            "formulation EA solver best ok run_s repeats compile_s cpu_rel err_m "
            "num_steps num_rejected_steps status"
        ).split(),
        f"Fig 9: wall time vs EA per formulation, k={k}, t1={t1} s, rtol=atol={tol:g}",
        notes=[
            "best: the jaxstring solver with the smallest total time over all EAs for "
            "that formulation; cpu_rel = run_s / fastest best-solver run at the "
            f"smallest EA (the paper's normalisation). Reference peer: {peer}.",
            f"err_m: max end-mass distance vs {ref_label} of the same formulation.",
            "run_s: median of `repeats` runs after a compile/warm-up run.",
        ],
    )
    fig, axes = common.new_figure(1, 1, w=6)
    ax = axes[0][0]
    for i, form in enumerate(formulations):
        for who, style in ((best[form], "-"), (f"{peer} [jax-band]", "--")):
            pts = [
                (r["EA"], r["cpu_rel"])
                for r in rows
                if r["formulation"] == form and r["solver"] == who and r["ok"]
            ]
            if pts:
                x, y = zip(*pts)
                ax.loglog(
                    x,
                    y,
                    style,
                    color=f"C{i}",
                    marker="o",
                    ms=3,
                    label=f"{LABEL[form]}: {who}",
                )
    ax.set_xlabel("EA (N)")
    ax.set_ylabel("wall time (1 = fastest at smallest EA)")
    ax.set_title(f"Fig 9: formulations, k={k}, rtol={tol:g}")
    ax.legend(fontsize=7)
    common.savefig(fig, f"fig9_formulations{tag}")
    return rows


if __name__ == "__main__":
    common.run_study(
        main, __doc__, lists={"formulations": str, "EAs": float, "solvers": str}
    )
