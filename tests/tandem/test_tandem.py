"""FPSO + shuttle tanker tandem (specs/tanker.md): loads, equilibria, stability,
limit cycles and the nonlinear compensator, against the spec's numbers.

Numbers tagged [P] in the spec come from an independent NumPy/SciPy prototype of
the same spec; the other references are the spec's own tables and formulas.
"""

import functools
import math
import re
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring.tandem import (
    ENVIRONMENTS,
    ConstantThrust,
    Hawser,
    MooredFPSO,
    NonlinearCompensator,
    OCIMFWind,
    ShortWingCurrent,
    Tandem,
    TurretMooring,
    fpso_hull,
    make_hull,
    shuttle_hull,
    tandem_controlled,
    tandem_equilibria,
    tandem_fishtail,
    tandem_fpso_alone,
    tandem_hopf,
)
from jaxstring.tandem.analysis import (
    classify,
    controlled_metrics,
    counts,
    find_equilibria,
    hopf_sweep,
    measure_limit_cycle,
    pitchfork_sweep,
    stability,
)
from jaxstring.tandem.autopilot import outputs
from jaxstring.tandem.scenes import current_field, environment, tandem_model
from jaxstring.tandem.vessels import VesselKinematics, current_at, ocimf_coefficients


TOL = 1e-8  # tsit5 tolerances of the simulations


def sim(scene, n_save, rtol=TOL, atol=TOL):
    ts = jnp.linspace(float(scene.t0), float(scene.t1), n_save)
    return js.simulate(scene, "tsit5", rtol=rtol, atol=atol, ts=ts, max_steps=500_000)


# ---------------------------------------------------------------------------
# Particulars and loads (spec sections 3 and 5)


def test_hull_particulars_match_spec_table():
    f, s = fpso_hull(), shuttle_hull()
    table = [
        (f.A11, 3.683e7), (f.A22, 2.850e8), (f.A66, 1.555e12), (f.I_z, 1.984e12),
        (s.m, 1.305e8), (s.A11, 1.427e7), (s.A22, 9.349e7), (s.A66, 3.215e11),
        (s.I_z, 5.097e11),
    ]  # fmt: skip
    for got, want in table:
        assert abs(float(got) - want) / want < 1.5e-3, (float(got), want)


def test_derived_check_values():
    # Spec section 5 "Derived check values" [P].
    model = tandem_model()
    cur = ShortWingCurrent()
    env = js.Environment(current=current_field(U_c=1.0))  # flowing south
    nu = jnp.zeros((2, 3))
    kin = lambda eta: VesselKinematics(eta, nu, current_at(0.0, eta, env), model)
    north = jnp.array([[0.0, 0.0, 0.0], [-400.0, 0.0, 0.0]])
    X = cur.forces(0.0, kin(north), env)
    assert abs(-float(X[1, 0]) - 17.8e3) < 0.05e3  # aligned shuttle drag
    beam = north.at[0, 2].set(math.pi / 2)
    Y = cur.forces(0.0, kin(beam), env)
    assert abs(float(Y[0, 1]) - 1.8e6) / 1.8e6 < 0.03  # FPSO beam current load
    wind = OCIMFWind(speed=15.0, direction=math.pi)  # head wind for a north heading
    W = wind.forces(0.0, kin(north), env)
    assert abs(-float(W[1, 0]) - 0.13e6) / 0.13e6 < 0.03
    # FPSO turret offset at 1 m/s head current (FPSO + shuttle drag): about 0.5 m.
    y0 = np.asarray(tandem_equilibria().y0)
    offset = abs(y0[0] + float(model.x_t))
    assert 0.45 < offset < 0.55
    # Hawser law: 0.2 MN at 1 m, 0.5 MN at 2.4 m, 4 MN at 10 m; d_ref = 81.47 m.
    h = Hawser()
    for delta, T in ((1.0, 0.202e6), (2.4, 0.5076e6), (10.0, 4.0e6)):
        assert abs(float(h.tension_of_stretch(delta)) - T) / T < 2e-3
    assert abs(float(h.l0 + h.stretch_for_tension(300e3)) - 81.47) < 0.005


def test_current_velocity_form_equals_angle_form():
    # Spec 3.1: the velocity form is algebraically the angle form (up to the
    # smoothing of |.|); check at U = 1 m/s over incidence angles, r = 0.
    h = fpso_hull()
    model = MooredFPSO(fpso=h)
    cur = ShortWingCurrent(yaw_rate_terms=False)
    env = js.Environment(current=current_field(U_c=1.0, beta_c=0.0))
    L, B, T, CB, S, CY, lp = 320.0, 54.5, 21.5, 0.85, 27447.0, 0.52, 0.05
    rho, tau = 1025.0, math.pi * 21.5 / 320.0
    for alpha in np.linspace(-3.0, 3.0, 13):
        # Current flows toward north; heading psi puts the flow at body angle
        # alpha = -psi (going-to angle of the water in body axes).
        psi = -alpha
        eta = jnp.array([[0.0, 0.0, psi]])
        still = jnp.zeros((1, 3))
        kin = VesselKinematics(eta, still, current_at(0.0, eta, env), model)
        F = np.asarray(cur.forces(0.0, kin, env))[0]
        U = math.sqrt(1.0 + 0.01**2)  # the velocity form's floored speed
        q = 0.5 * rho * L * T * U**2
        Cf = 0.09375 / (math.log10(U * L / 1e-6) - 2) ** 2
        sa, ca = math.sin(alpha), math.cos(alpha)
        X = q * (Cf * S / (L * T) * ca + tau / 8 * (math.cos(3 * alpha) - ca))
        Y = q * (
            (CY - tau / 2) * sa * abs(sa)
            + tau / 2 * sa**3
            + tau * (1 + 0.4 * CB * B / T) * sa * abs(ca)
        )
        N = (
            q
            * L
            * (
                -lp * (CY - tau / 2) * sa * abs(sa)
                - tau * sa * ca
                - ((1 + abs(ca)) / 2) ** 2 * tau * (0.5 - 2.4 * T / L) * sa * abs(ca)
            )
        )
        scale = q
        np.testing.assert_allclose(F[:2], [X, Y], atol=2e-3 * scale)
        assert abs(F[2] - N) < 2e-3 * scale * L


def test_ocimf_fit_within_0p05_of_table():
    # Spec 3.2 digitised OCIMF table vs the smooth Fourier fit (max error <= 0.05).
    theta = np.radians(np.arange(0, 181, 20))
    table = {
        "loaded": (
            [-0.95, -0.83, -0.60, -0.34, -0.08, 0.15, 0.28, 0.50, 0.75, 0.76],
            [0, -0.19, -0.42, -0.63, -0.71, -0.72, -0.68, -0.50, -0.28, 0],
            [0, 0.017, 0.050, 0.080, 0.103, 0.127, 0.163, 0.160, 0.100, 0],
        ),
        "ballast": (
            [-0.86, -0.60, -0.32, -0.12, -0.04, 0.08, 0.27, 0.45, 0.61, 0.61],
            [0, -0.31, -0.67, -0.88, -0.98, -0.96, -0.79, -0.57, -0.30, 0],
            [0, -0.043, -0.061, -0.057, -0.007, 0.078, 0.133, 0.154, 0.103, 0],
        ),
    }
    # The spec's fit coefficients (4 decimals) reach 0.053 for the ballast C_X at
    # 20 deg; the loaded set (the default) is within 0.05.
    for loading, bound in (("loaded", 0.05), ("ballast", 0.055)):
        fit = ocimf_coefficients(jnp.asarray(theta), loading)
        for c, ref in zip(fit, table[loading]):
            assert np.max(np.abs(np.asarray(c) - np.asarray(ref))) <= bound


def test_absent_effect_is_not_traced():
    # A scene without wind traces no wind operations; with a zero wind the
    # vector field is the same up to the air drag of the (resting) hulls.
    sc = tandem_equilibria()
    windy = tandem_equilibria(V_w=1e-12)
    y = sc.y0
    f0 = lambda y: sc.vector_field(0.0, y)
    f1 = lambda y: windy.vector_field(0.0, y)
    n0 = len(jax.make_jaxpr(f0)(y).eqns)
    n1 = len(jax.make_jaxpr(f1)(y).eqns)
    assert n1 > n0 + 20
    np.testing.assert_allclose(f0(y), f1(y), rtol=0, atol=1e-9)


# ---------------------------------------------------------------------------
# S0, S2: stability of the aligned equilibria


def test_S0_pitchfork_at_0p355():
    xs = np.array([0.33, 0.35, 0.37, 0.40])
    xs, lead, x_star = pitchfork_sweep(
        lambda x: tandem_fpso_alone(x_t_over_L=x, psi0_deg=0.0), xs
    )
    assert np.all(np.abs(lead.imag) < 1e-12)  # a real eigenvalue crosses zero
    assert abs(x_star - 0.355) <= 0.01, x_star
    assert lead[0].real > 0 and lead[-1].real < 0  # aft unstable, forward stable
    # At the default 0.40 L1 the leading eigenvalue is -3.4e-4 1/s [P].
    assert abs(lead[-1].real + 3.4e-4) < 0.05 * 3.4e-4


def test_S2_eigenvalues_of_current_only_equilibrium():
    sc = tandem_equilibria()
    assert abs(float(sc.observables(sc.y0)["tension"]) - 17.8e3) < 0.05e3
    eigs, kind = stability(sc, np.asarray(sc.y0))
    assert kind == "oscillatory unstable"
    spec = [
        7.17e-4 + 1.852e-3j,
        -4.28e-4 + 4.152e-2j,
        -6.36e-4 + 1.385e-2j,
        -3.35e-3 + 2.447e-2j,
        -3.9e-4,
        -1.18e-3,
        -4.17e-3,
        -9.76e-3,
    ]
    for s in spec:
        got = eigs[np.argmin(np.abs(eigs - s))]
        assert abs(got - s) <= 0.02 * abs(s), (got, s)
    # The leading pair is the fishtail mode: period 3390 s.
    assert abs(2 * math.pi / abs(eigs[0].imag) - 3390) < 0.02 * 3390


# ---------------------------------------------------------------------------
# S1: equilibria over wind


@functools.cache
def equilibria(V_w, Delta_w):
    return find_equilibria(tandem_equilibria(V_w=V_w, Delta_w_deg=Delta_w))


# (V_w, Delta_w) -> spec (taut, admissible, stable) [P]
S1_QUICK = {(15.0, 90.0): (4, 4, 1), (20.0, 120.0): (6, 5, 2), (15.0, 150.0): (8, 6, 2)}


@pytest.mark.parametrize("cell", sorted(S1_QUICK))
def test_S1_counts_and_stability(cell):
    got = counts(equilibria(*cell))
    want = S1_QUICK[cell]
    assert all(abs(g - w) <= 1 for g, w in zip(got, want)), (got, want)
    assert got[2] == want[2]


def test_S1_weathervane_example_and_mirror_symmetry():
    # V_w = 15 m/s, Delta_w = 90 deg: one stable weathervaned equilibrium with
    # psi1 = 41 deg, psi2 = 29 deg, T = 216 kN [P]; -Delta_w gives the mirror image.
    eqs = equilibria(15.0, 90.0)
    stable = [e for e in eqs if e.stable and e.admissible]
    assert len(stable) == 1
    e = stable[0]
    assert abs(e.headings_deg[0] - 41) < 1 and abs(e.headings_deg[1] - 29) < 1
    assert abs(e.tension - 216e3) < 2e3
    others = [e for e in eqs if not e.stable]
    assert all(o.kind in ("saddle", "oscillatory unstable") for o in others)
    mirror = equilibria(15.0, -90.0)
    assert len(mirror) == len(eqs)
    for e in eqs:
        y = e.y.reshape(2, 6)
        ym = y * np.array([1, -1, -1, 1, -1, -1])  # reflect east and angles
        d = [np.max(np.abs(m.y.reshape(2, 6)[:, :2] - ym[:, :2])) for m in mirror]
        j = int(np.argmin(d))
        assert d[j] < 1e-3 and mirror[j].kind == e.kind


def test_S1_scenes_in_one_call_are_each_scenes_equilibria():
    # find_equilibria_map (the scenes vmapped, the stability Jacobian taken once
    # after the Newton loop) against find_equilibria of each scene (the Jacobian
    # from the loop's last pass), and both Jacobians against the vector field's
    # own at the roots (`stability`).
    from jaxstring.tandem.analysis import find_equilibria_map

    cells = [(15.0, 90.0), (20.0, 120.0)]
    both = find_equilibria_map(
        [tandem_equilibria(V_w=v, Delta_w_deg=d) for v, d in cells]
    )
    for cell, eqs in zip(cells, both):
        one = equilibria(*cell)
        assert [e.kind for e in eqs] == [e.kind for e in one]
        sc = tandem_equilibria(V_w=cell[0], Delta_w_deg=cell[1])
        for a, b in zip(eqs, one):
            np.testing.assert_allclose(a.y, b.y, rtol=0, atol=1e-9)
            eigs, kind = stability(sc, b.y)
            assert kind == b.kind
            scale = np.max(np.abs(eigs))
            for got in (a.eigenvalues, b.eigenvalues):
                assert np.max(np.abs(got - eigs)) < 1e-9 * scale


def _mirror(y):
    # Reflect east and the angles: the image of a state under y -> -y.
    return y.reshape(2, 6) * np.array([1, -1, -1, 1, -1, -1])


def _distance(y, z):
    """Max of position (m) and wrapped heading (rad) differences of two states."""
    y, z = y.reshape(2, 6), z.reshape(2, 6)
    dang = np.angle(np.exp(1j * (y[:, 2] - z[:, 2])))
    return max(np.max(np.abs(y[:, :2] - z[:, :2])), np.max(np.abs(dang)))


@pytest.mark.parametrize("V_w", [15.0, 20.0])
def test_S1_opposing_wind_mirror_pairs_and_jackknife(V_w):
    # Wind against the current: the problem is mirror-symmetric, so the roots are
    # either on the axis or come in mirror pairs, each an isolated root (regular
    # Jacobian) of the load balance. Two mirror-image stable jack-knifed states:
    # FPSO nearly beam-on (|psi1| ~ 90-104 deg), shuttle at 23-50 deg the other
    # way [P]. Admissible and stable counts as the spec (7 and 2).
    from jaxstring.tandem.analysis import q_from_state, residual

    sc = tandem_equilibria(V_w=V_w, Delta_w_deg=180.0)
    eqs = equilibria(V_w, 180.0)

    @eqx.filter_jit
    def check(sc, ys):
        qs = jax.vmap(lambda y: q_from_state(y, 2))(ys)
        r = jax.vmap(lambda q: jnp.max(jnp.abs(residual(q, sc))))(qs)
        J = jax.vmap(jax.jacfwd(lambda q: residual(q, sc)))(qs)
        return r, jnp.linalg.svd(J, compute_uv=False)[:, -1]

    res, smin = check(sc, jnp.asarray(np.stack([e.y for e in eqs])))
    assert np.all(np.asarray(res) < 1e-9) and np.all(np.asarray(smin) > 1e-3)
    for e in eqs:
        m = min(eqs, key=lambda o: _distance(o.y, _mirror(e.y)))
        assert _distance(m.y, _mirror(e.y)) < 1e-6
        assert m.kind == e.kind and abs(m.tension - e.tension) < 1e-3 * e.tension
    taut, adm, stab = counts(eqs)
    assert abs(adm - 7) <= 1 and stab == 2
    st = [e for e in eqs if e.stable and e.admissible]
    assert _distance(st[0].y, _mirror(st[1].y)) < 1e-6
    for e in st:
        p1, p2 = e.headings_deg
        assert 88 < abs(p1) < 106 and 21 < abs(p2) < 52 and p1 * p2 < 0


# Its own compilation of the exported program (about 15 s): slow.
@pytest.mark.slow
def test_equilibria_through_a_saved_program_are_the_same(tmp_path):
    # As a process with the cache on finds them: through a saved program.
    from jaxstring import _programs

    _programs.set_program_folder(str(tmp_path))
    try:
        saved = find_equilibria(tandem_equilibria(V_w=15.0, Delta_w_deg=90.0))
    finally:
        _programs.set_program_folder(None)
    assert list(tmp_path.glob("*.program"))
    direct = equilibria(15.0, 90.0)
    assert [e.kind for e in saved] == [e.kind for e in direct]
    for a, b in zip(saved, direct):
        np.testing.assert_allclose(a.y, b.y, rtol=1e-9, atol=1e-9)
        assert abs(a.tension - b.tension) <= 1e-9 * abs(b.tension)


def test_S1_find_equilibria_method():
    sc = tandem_equilibria(V_w=15.0, Delta_w_deg=90.0)
    with pytest.raises(ValueError, match="`method`"):
        find_equilibria(sc, method="hybrd")


@pytest.mark.slow
def test_S1_dogleg_roots_are_newton_roots():
    # The Powell dogleg trust region (optimistix analogue of MINPACK hybrd, the
    # prototype's "hybrid" solver) stays near its starts: at Delta_w = 180 deg every
    # root it finds is one of Newton's, including both stable jack-knifed states.
    newton = equilibria(15.0, 180.0)
    dogleg = find_equilibria(
        tandem_equilibria(V_w=15.0, Delta_w_deg=180.0), method="dogleg"
    )
    for e in dogleg:
        assert min(_distance(e.y, o.y) for o in newton) < 1e-6
    assert counts(dogleg)[1:] == counts(newton)[1:]


# The specification, in the shared folder beside the repository.
SPEC_FILE = Path(__file__).resolve().parents[3] / "shared" / "specs" / "tanker.md"


def spec_s1_table():
    """The spec's S1 table, read from the spec itself: {(V_w, Delta_w): (taut,
    admissible, stable)}."""
    if not SPEC_FILE.exists():
        pytest.skip(f"the tanker spec is not at {SPEC_FILE}")
    table = {}
    for line in SPEC_FILE.read_text().splitlines():
        m = re.match(r"\|\s*(\d+) m/s\s*\|(.*)\|\s*$", line)
        if not m:
            continue
        for j, cell in enumerate(m.group(2).split("|")):
            counts = [int(n) for n in re.findall(r"\d+", cell)]
            if len(counts) == 3:
                table[(float(m.group(1)), 30.0 * j)] = tuple(counts)
    assert len(table) == 29, "the spec's S1 table has 1 + 4 x 7 cells"
    return table


def test_packaged_S1_table_is_the_specs():
    from jaxstring.cli.tandem import S1_SPEC

    assert S1_SPEC == spec_s1_table()


@pytest.mark.slow
def test_S1_full_table():
    from jaxstring.cli.tandem import equilibrium_table

    S1_SPEC = spec_s1_table()
    cells = sorted(S1_SPEC)
    results = equilibrium_table(cells)
    for cell, eqs in zip(cells, results):
        got, want = counts(eqs), S1_SPEC[cell]
        # Stability matches in every cell.
        assert got[2] == want[2], (cell, got, want)
        if cell[1] == 180.0:
            # Wind exactly against the current: Newton finds more equilibria than
            # the prototype's "Newton/hybrid" search, all genuine (mirror pairs of
            # regular roots, test above) and all extra ones at 10-20 m/s with
            # overlapping hulls. At 5 m/s the two extra admissible ones are the
            # +-6.9 deg pitchfork pair of the aligned state (pitchfork at
            # V_w ~ 3.5 m/s), found by every solver tried (Newton, Dogleg, scipy
            # hybr; results/tanker_equilibria_methods.md). Taut: a superset;
            # admissible within 1 from 10 m/s on.
            assert got[0] >= want[0] - 1, (cell, got, want)
            if cell[0] >= 10.0:
                assert abs(got[1] - want[1]) <= 1, (cell, got, want)
        else:
            assert all(abs(g - w) <= 1 for g, w in zip(got, want)), (cell, got, want)


# ---------------------------------------------------------------------------
# S3: fishtailing and the Hopf bifurcation


@functools.cache
def fishtail_run():
    return sim(tandem_fishtail(t1=60000.0), 6001)


def test_S3a_fishtailing_limit_cycle():
    traj = fishtail_run()
    assert traj.ok, traj.status
    m = measure_limit_cycle(traj, 36000.0)
    # Spec S3a [P] ranges ("about 3400-3500 s" for the period; the cycle is
    # slightly irregular, so allow 1 % on the period and the excursion: their
    # measured peaks move with the rounding of the run, e.g. 175.26 m with
    # XLA:CPU's elemental emitter).
    assert 3400 * 0.99 <= m["period"] <= 3500 * 1.01, m
    assert 13 <= m["shuttle_yaw"] <= 18, m
    assert 2 <= m["fpso_yaw"] <= 4, m
    assert 150 * 0.99 <= m["lateral_excursion"] <= 175 * 1.01, m
    # The span's least value over six cycles is one cycle's deepest approach, the
    # quantity that moves most with rounding: 28.5 m on an AMD EPYC (the other
    # cycles' minima 29.8-71 m), above 29 m on an Intel Xeon; 3 % allowed, as on the
    # tension.
    assert 29 * 0.97 <= m["span_min"] <= 60 and 80 <= m["span_max"] <= 86, m
    assert m["tension_min"] < 1.0 and 0.8e6 * 0.97 <= m["tension_max"] <= 0.9e6 * 1.03


def test_S3b_hopf_point():
    Fs = np.array([30e3, 40e3, 50e3, 60e3])
    Fs, _, lead, F_star = hopf_sweep(lambda F: tandem_hopf(F_ast=F), Fs)
    assert abs(F_star - 43e3) <= 0.10 * 43e3, F_star
    w = float(np.interp(F_star, Fs, np.abs(lead.imag)))
    assert abs(w - 3.34e-3) <= 0.05 * 3.34e-3
    assert lead[0].real > 0 and lead[-1].real < 0  # unstable below, stable above


def test_classify():
    assert classify(np.array([-1.0, -2 + 1j, -2 - 1j])) == "stable"
    assert classify(np.array([1e-3, -2 + 1j, -2 - 1j])) == "saddle"
    assert classify(np.array([-1.0, 1e-3 + 1j, 1e-3 - 1j])) == "oscillatory unstable"


# ---------------------------------------------------------------------------
# S4: the nonlinear compensator


@functools.cache
def controlled_run(env, law="B"):
    # 6000 s: the zero dynamics settle in ~4200 s for wind against current.
    sc = tandem_controlled(env=env, law=law, t1=6000.0)
    return sc, sim(sc, 3001)


# Final FPSO headings [P] (deg) and steady surge force range (N).
S4_PSI1 = {"current": 0.0, "wind15_90": 44.6, "wind15_180": 62.5}


@pytest.mark.parametrize("env", sorted(ENVIRONMENTS))
def test_S4_acceptance(env):
    sc, traj = controlled_run(env)
    assert traj.ok, traj.status
    ctl = sc.effects[-1]
    m = controlled_metrics(traj, float(ctl.d_ref), ctl.X_max, ctl.N_max, 3000.0)
    assert m["span_error"] < 0.5 and m["heading_error"] < 0.5, m
    assert m["clearance_min"] > 0, m
    assert m["X_peak"] <= float(ctl.X_max) and m["N_peak"] <= float(ctl.N_max), m
    assert m["ok"]
    # Spec 4.4 [P]: span never below the initial 81.0 m; the actuator saturates
    # in yaw at the start; the steady surge force is astern, -270 to -390 kN.
    assert m["span_min"] >= 81.0 - 1e-6, m
    assert m["N_peak"] > 0.99 * float(ctl.N_max)
    assert -395e3 <= m["X_final"] <= -265e3, m
    if env in S4_PSI1:
        assert abs(m["psi1_final"] - S4_PSI1[env]) < 0.5, m


def test_law_B_gives_the_linear_closed_loop():
    # Once unsaturated, law B makes e'' = -K_P e - K_D e' exact: with omega = 0.05,
    # zeta = 1, e(t) = (e0 + (e0' + w e0) s) exp(-w s) on both channels.
    sc, traj = controlled_run("wind15_90")
    ctl = sc.effects[-1]
    ts = np.asarray(traj.ts)
    i0 = int(np.searchsorted(ts, 100.0))
    yo, yd, _ = outputs(sc.model, traj.ys[i0])
    e0 = np.asarray(yo) - np.array([float(ctl.d_ref), 0.0])
    w = 0.05
    s = ts[i0:] - ts[i0]
    pred = (e0[None] + (np.asarray(yd) + w * e0)[None] * s[:, None]) * np.exp(
        -w * s[:, None]
    )
    span_err = np.asarray(traj.span)[i0:] - float(ctl.d_ref)
    head_err = np.asarray(traj.heading_error)[i0:]
    assert np.max(np.abs(span_err - pred[:, 0])) < 1e-4 * abs(e0[0])
    assert np.max(np.abs(head_err - pred[:, 1])) < 1e-5 * abs(e0[1])


@pytest.mark.slow
def test_S4_law_A_baseline():
    sc, traj = controlled_run("wind15_90", "A")
    ctl = sc.effects[-1]
    m = controlled_metrics(traj, float(ctl.d_ref), ctl.X_max, ctl.N_max, 3000.0)
    assert m["ok"], m


@pytest.mark.slow
def test_gradient_of_collision_cost_wrt_gains():
    # Slow only through compilation (reverse mode through diffrax, ~40 s CPU).
    # Cost = int softplus(d_safe - d)^2 dt over the first 300 s of S4 (15 m/s
    # crossed wind), gradient w.r.t. (K_P, K_D) of law B through diffrax.
    sc = tandem_controlled(env="wind15_90", t1=300.0)
    ts = jnp.linspace(0.0, 300.0, 151)

    def cost(gains):
        ctl = eqx.tree_at(
            lambda c: (c.K_P, c.K_D), sc.effects[-1], (gains[:2], gains[2:])
        )
        scene = eqx.tree_at(lambda s: s.effects[-1], sc, ctl)
        traj = js.simulate(scene, "tsit5", rtol=1e-12, atol=1e-12, ts=ts)
        f = jax.nn.softplus(82.0 - traj.span) ** 2
        return jnp.sum(0.5 * (f[1:] + f[:-1]) * jnp.diff(ts))

    g0 = jnp.array([0.0025, 0.0025, 0.1, 0.1])
    grad = np.asarray(jax.grad(cost)(g0))
    assert np.all(np.isfinite(grad))
    for i in range(4):
        h = 1e-3 * float(g0[i])
        e = jnp.zeros(4).at[i].set(h)
        fd = float((cost(g0 + e) - cost(g0 - e)) / (2 * h))
        assert abs(grad[i] - fd) <= 1e-4 * abs(fd), (i, grad[i], fd)


# ---------------------------------------------------------------------------
# Bad input


@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: environment(U_c=-1.0), "`U_c`"),
        (lambda: js.Environment(rho_water=-1025.0), "`rho_water`"),
        (lambda: js.Environment(rho_air=0.0), "`rho_air`"),
        (lambda: OCIMFWind(speed=-5.0), "`speed`"),
        (lambda: tandem_equilibria(U_c=-1.0), "`U_c`"),
        (lambda: tandem_equilibria(V_w=-1.0), "`V_w`"),
        (lambda: Hawser(l0=-80.0), "`l0`"),
        (lambda: Hawser(k_h=0.0), "`k_h`"),
        (lambda: shuttle_hull(L=-250.0), "`L`"),
        (lambda: shuttle_hull(B=0.0), "`B`"),
        (lambda: fpso_hull(m=0.0), "`m`"),
        (
            lambda: make_hull(
                L=100.0, B=10.0, T=5.0, C_B=0.8, S=1e3, A_F=1.0, A_L=1.0, m=-1.0
            ),
            "`m`",
        ),  # fmt: skip
        (
            lambda: Tandem(fpso=fpso_hull(), shuttle=shuttle_hull(), x_h1=-200.0),
            "`x_h1`",
        ),  # fmt: skip
        (
            lambda: Tandem(fpso=fpso_hull(), shuttle=shuttle_hull(), x_h2=130.0),
            "`x_h2`",
        ),  # fmt: skip
        (lambda: Tandem(fpso=fpso_hull(), shuttle=shuttle_hull(), x_t=170.0), "`x_t`"),
        (lambda: TurretMooring(k_m=-1.0), "`k_m`"),
        (lambda: ConstantThrust(X_max=0.0), "`X_max`"),
        (lambda: NonlinearCompensator(d_ref=-1.0), "`d_ref`"),
        (lambda: tandem_controlled(env="storm"), "env"),
        (lambda: OCIMFWind(loading=("loaded", "empty")), "`loading`"),
    ],
)
def test_bad_input_raises(make, name):
    with pytest.raises(ValueError, match=name):
        make()
