"""Smoke test of the experiments/ scripts at their --quick sizes, with numbers checked.

Every script's ``main(quick=True)`` runs (tables and figures go to a temporary
directory), and its results are checked against physics or an independent solver:
the external references agree with jaxstring on the identical right-hand side, the
band Jacobian equals the dense one, MoorDyn and jaxstring swing the same pendulum.
Timings are never asserted (speed is shown by the scripts themselves). On the shared
2-core machine the whole module takes several minutes, so every script's run is
marked slow; the band-Jacobian check stays in the default run.

The quick sizes share one compiled jaxstring solve (angle formulation, k = 8,
Kvaerno5, 41 save times) wherever they can, to stay within CI time.
"""

import importlib
import importlib.util
import math
import os

import numpy as np
import pytest


HAS_SCIPY = importlib.util.find_spec("scipy") is not None
HAS_SUNDAE = importlib.util.find_spec("sksundae") is not None
HAS_MOORDYN = importlib.util.find_spec("moordyn") is not None
HAS_NUMBA = importlib.util.find_spec("numba") is not None


@pytest.fixture(scope="module", autouse=True)
def results_in_tmp(tmp_path_factory):
    old = os.environ.get("JAXSTRING_RESULTS_DIR")
    os.environ["JAXSTRING_RESULTS_DIR"] = str(tmp_path_factory.mktemp("results"))
    import matplotlib

    matplotlib.use("Agg")
    yield os.environ["JAXSTRING_RESULTS_DIR"]
    if old is None:
        del os.environ["JAXSTRING_RESULTS_DIR"]
    else:
        os.environ["JAXSTRING_RESULTS_DIR"] = old


def _module(name):
    return importlib.import_module(name)


def _files(results, stem):
    return {
        ext: os.path.exists(os.path.join(results, f"{stem}.{ext}"))
        for ext in ("csv", "md", "png")
    }


@pytest.mark.skipif(not HAS_SCIPY, reason="scipy (bench extra) not installed")
def test_band_jacobian_equals_dense():
    import jaxstring
    from jaxstring.testing import references as refs

    for form in ("displacement", "natural", "angle"):
        scene = jaxstring.string_pendulum(formulation=form, k=5, EA=1e5)
        rhs = refs.JaxRHS(scene)
        rhs.compile()
        y = rhs.y0 + 1e-2 * np.random.default_rng(1).standard_normal(rhs.n)
        dense = np.asarray(rhs._jac(0.3, y))
        band = np.zeros_like(dense)
        band[rhs.band_i, rhs.band_j] = rhs.jac_band_values(0.3, y)
        np.testing.assert_allclose(
            band, dense, rtol=1e-12, atol=1e-9 * np.abs(dense).max()
        )
        packed = rhs.jac_packed(0.3, y)
        for i, j in [(0, 0), (3, 1), (rhs.n - 1, rhs.n - 2)]:
            if abs(i - j) <= max(rhs.lband, rhs.uband):
                assert packed[rhs.uband + i - j, j] == pytest.approx(dense[i, j])


@pytest.mark.slow
@pytest.mark.skipif(not HAS_SCIPY, reason="scipy (bench extra) not installed")
def test_references_quick_agree_with_jaxstring(results_in_tmp):
    rows = _module("references").main(quick=True)
    peers = [r for r in rows if r["peer"] != "jaxstring kvaerno5"]
    assert peers and all(r["ok"] for r in peers)
    # rtol = atol = 1e-7 on a 1 m pendulum: independent integrators of the identical
    # equations agree to a few 1e-6 m (the tolerance times the error growth).
    assert max(r["err_vs_kvaerno5_m"] for r in peers) < 3e-5
    assert all(_files(results_in_tmp, "references_quick")[e] for e in ("csv", "md"))


@pytest.mark.slow
@pytest.mark.skipif(
    not (HAS_SCIPY and HAS_SUNDAE and HAS_NUMBA),
    reason="scipy, scikit-sundae, numba (bench extra)",
)
def test_fig10_quick(results_in_tmp):
    rows = _module("fig10_integrators").main(
        quick=True, solvers=["kvaerno5", "implicit_euler_fixed"]
    )
    by = {(r["EA"], r["solver"]): r for r in rows}
    for EA in (1e4, 1e6):
        k5 = by[(EA, "kvaerno5")]
        ie = by[(EA, "implicit_euler_fixed")]
        assert k5["ok"] and ie["ok"]
        assert ie["num_steps"] == 40  # 0.2 s / dt 0.005
        # adaptive 5th order at 1e-7 vs first order at dt = 5 ms: orders apart
        assert k5["err_m"] < 1e-5 < ie["err_m"] < 0.1
        # CVODE-numba at rtol 1e-7 lands within 1e-6 m of its own run at 1e-11
        cvode = [r for r in rows if r["EA"] == EA and r["solver"].startswith("CVODE-")]
        assert len(cvode) == 1 and cvode[0]["ok"] and cvode[0]["err_m"] < 1e-6
    assert all(_files(results_in_tmp, "fig10_integrators_quick").values())


@pytest.mark.slow
def test_esdirk_step_quick(results_in_tmp):
    rows = _module("esdirk_step").main(quick=True)
    by = {r["solver"]: r for r in rows}
    mine, theirs = by["written out"], by["diffrax"]
    assert mine["ok"] and theirs["ok"]
    # the same tableau and controller: equally accurate (rtol 1e-6 against a
    # Rodas5P run at 1e-11) in about as many steps
    assert mine["err_m"] < 1e-6 and theirs["err_m"] < 1e-6
    assert abs(mine["accepted"] - theirs["accepted"]) <= 0.2 * theirs["accepted"]
    assert os.path.exists(os.path.join(results_in_tmp, "esdirk_step_quick.md"))


@pytest.mark.slow
@pytest.mark.skipif(
    not (HAS_SUNDAE and HAS_NUMBA), reason="scikit-sundae, numba (bench extra)"
)
def test_fig9_quick(results_in_tmp):
    mod = _module("fig9_formulations")
    rows = mod.main(quick=True)
    by = {(r["formulation"], r["EA"], r["solver"].split(" [")[0]): r for r in rows}
    codes = ("kvaerno5", mod.CVODE, mod.CALLBACK)
    for form in ("displacement", "angle"):
        for EA in (1e4, 1e6):
            for code in codes:
                r = by[(form, EA, code)]
                # jaxstring and the callback IDA against CVODE on the independent
                # numba equations at 1e-11: the models agree and each code meets
                # rtol 1e-7 (measured 4e-9 ... 5e-7 m)
                assert r["ok"] and r["err_m"] < 1e-5, (form, EA, code, r["err_m"])
                assert r["cpu_s"] > 0 and np.isfinite(r["x_cvode_cpu"])
        # Kvaerno5's attempted steps barely change from EA = 1e4 to 1e6 at k = 8
        # (measured 63 -> 57 in displacement, 49 -> 47 in (eps, phi) variables)
        k5 = [by[(form, EA, "kvaerno5")]["attempted"] for EA in (1e4, 1e6)]
        assert 0 < k5[1] < 1.5 * k5[0], (form, k5)
    assert all(_files(results_in_tmp, "fig9_formulations_quick").values())
    # The formulation gap at the paper's settings is asserted on step counts in
    # tests/pendulum/test_formulation_gap.py.


@pytest.mark.slow
@pytest.mark.skipif(not HAS_SUNDAE, reason="scikit-sundae (bench extra) not installed")
def test_work_precision_quick(results_in_tmp):
    rows, head = _module("work_precision").main(quick=True)
    for who in ("kvaerno5", "cvode-BDF [jax-band]"):
        errs = [
            r["err_m"]
            for r in sorted(rows, key=lambda r: -r["tol"])
            if r["solver"] == who
        ]
        # tightening the tolerance 100x must shrink the error
        assert len(errs) == 2 and errs[1] < errs[0]
    assert head and all(r["target_m"] > 0 for r in head)
    assert all(_files(results_in_tmp, "work_precision_quick").values())


@pytest.mark.slow
@pytest.mark.skipif(not HAS_SUNDAE, reason="scikit-sundae (bench extra) not installed")
def test_scaling_quick(results_in_tmp):
    mod = _module("scaling_k")
    assert mod.fit_exponent([10, 20, 40], [1.0, 4.0, 16.0]) == pytest.approx(2.0)
    rows, exps = mod.main(quick=True)
    assert all(r["ok"] for r in rows)
    assert {e["solver"] for e in exps} >= {"kvaerno5"}
    assert all(math.isfinite(e["exponent"]) for e in exps)
    if not (HAS_NUMBA and HAS_SUNDAE):
        return
    # The numba peer runs at every k from the same start and lands where jaxstring
    # does; the ratio columns are the quotient of the two runs' medians.
    for k in (4, 8):
        js = next(r for r in rows if r["k"] == k and r["solver"] == "kvaerno5")
        cv = next(r for r in rows if r["k"] == k and r["solver"].startswith("CVODE"))
        assert cv["solver"] == "CVODE-numba [band DQ Jacobian]" and cv["diff_m"] == 0
        assert js["diff_m"] < 1e-5
        assert js["x_cvode_wall"] == pytest.approx(js["run_s"] / cv["run_s"])
        assert js["x_cvode_cpu"] == pytest.approx(js["cpu_s"] / cv["cpu_s"])
    assert any(e["solver"].startswith("CVODE-numba") for e in exps)


@pytest.mark.slow
@pytest.mark.skipif(not HAS_MOORDYN, reason="moordyn (bench extra) not installed")
def test_moordyn_quick_same_swing(results_in_tmp):
    rows = _module("moordyn_pendulum").main(quick=True)
    md = [r for r in rows if r["code"].startswith("MoorDyn")]
    js = [r for r in rows if r["code"].startswith("jaxstring")]
    assert md and js and all(r["ok"] for r in rows)
    # After 4 s the 100 m pendulum (period ~20 s) has swung from x = 9.94 m to ~3 m;
    # MoorDyn and jaxstring must agree to centimetres (different lumping details).
    assert 2.0 < md[0]["x_end_m"] < 5.0
    assert all(r["diff_vs_moordyn_m"] < 0.02 for r in js)
