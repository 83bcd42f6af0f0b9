"""The analytic elastic catenary (`jaxstring.lines.catenary`), checked with numbers:

- against MoorPy's `moorpy.Catenary.catenary` (the same equations, Jonkman 2007)
  over taut, slack-with-seabed-contact, friction, bunched, flat, nearly vertical,
  buoyant and free-hanging lines: HF, VF, HA, VA within 1e-8 of the tension;
- the inextensible catenary (with and without seabed contact) as EA grows, the
  straight elastic bar as W -> 0, and the vertical line's closed forms;
- the Jacobian w.r.t. XF, ZF, L, EA, W, CB (implicit-function theorem) against
  Richardson-extrapolated central differences within 1e-6; forward = reverse;
- vmap equals a loop; no NaN at zero horizontal span, and the 3-D force's
  stiffness there (a vertical tendon's k = 1/(dX/dHF)) against differences;
- the profile ends at the fairlead with the end tensions, and matches MoorPy's;
- the OC3-Hywind deck (lines.txt): fairlead and anchor tensions as MoorPy's
  System gives them (737.2 / 911.4 kN);
- bad input raises a ValueError naming the argument, its value and the range.

The 2-D checks share one compiled function (values and Jacobian of a padded
batch), so that the file compiles a handful of functions in all.
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring  # noqa: F401  (float64)
from jaxstring import lines
from jaxstring.lines.catenary import (
    CatenarySolution,
    catenary,
    catenary_forces,
    catenary_points,
    catenary_profile,
    catenary_stiffness,
)


B = 256  # every batch is padded to this size: one compilation
NAMES = ("XF", "ZF", "L", "EA", "W", "CB")

# OC3-Hywind line (lines.txt): 0.09 m, 77.7066 kg/m, EA 384.243 MN, 902.2 m; with
# MoorPy's g = 9.81 and the deck's 1025 kg/m^3
W_OC3 = (77.7066 - 1025.0 * math.pi / 4 * 0.09**2) * 9.81
EA_OC3 = 384.243e6

# (XF, ZF, L, EA, W, CB, anchor_on_seabed), by case class
CASES = {
    "taut": [
        (400.0, 300.0, 495.0, 1e8, 1000.0, 0.0, True),
        (600.0, 250.0, 640.0, 5e8, 800.0, 0.0, True),
        (870.0, 250.0, 902.2, EA_OC3, W_OC3, 0.0, True),
        (400.0, 300.0, 480.0, 1e9, 1000.0, 0.0, True),
    ],
    "seabed contact": [
        (848.67, 250.0, 902.2, EA_OC3, W_OC3, 0.0, True),
        (800.0, 250.0, 902.2, EA_OC3, W_OC3, 0.0, True),
        (370.0, 40.0, 400.0, 2e7, 300.0, 0.0, True),
    ],
    "seabed friction": [
        (848.67, 250.0, 902.2, EA_OC3, W_OC3, 1.0, True),  # anchor tension > 0
        (855.0, 250.0, 902.2, EA_OC3, W_OC3, 0.3, True),
        (800.0, 250.0, 902.2, EA_OC3, W_OC3, 1.0, True),  # slack at the anchor
    ],
    "bunched": [
        (600.0, 100.0, 800.0, 5e8, 1500.0, 0.0, True),
        (500.0, 100.0, 700.0, 1e9, 1200.0, 0.5, True),
    ],
    "flat": [
        (905.0, 0.0, 902.2, EA_OC3, W_OC3, 0.0, True),
        (905.0, 0.0, 902.2, EA_OC3, W_OC3, 0.5, True),
        (905.0, 0.0, 902.2, EA_OC3, W_OC3, 5.0, True),
    ],
    "nearly vertical": [
        (0.3, 300.0, 320.0, 1e9, 800.0, 0.0, False),
        (0.5, 300.0, 299.9, 1e9, 800.0, 0.0, True),
        (1.0, 200.0, 260.0, 1e8, 500.0, 0.0, False),
    ],
    "buoyant": [
        (300.0, 200.0, 400.0, 1e8, -200.0, 0.0, True),
        (250.0, -100.0, 300.0, 1e8, -50.0, 0.0, False),
        (150.0, 50.0, 170.0, 1e7, -800.0, 0.0, True),
    ],
    "free hanging": [
        (300.0, -50.0, 400.0, 1e8, 500.0, 0.0, False),
        (300.0, 100.0, 340.0, 1e9, 2000.0, 0.0, False),
    ],
}


def _fields(p, on):
    s = catenary(*p, on)
    return jnp.stack([s.HF, s.VF, s.HA, s.VA]), (s.LB, s.residual, s.converged)


@functools.cache
def _solver():
    """(values (B, 4), Jacobian (B, 4, 6), (LB, residual, converged)) of a batch."""

    def g(p, on):
        v, aux = _fields(p, on)
        return v, (v, aux)

    def f(p, on):
        J, (v, aux) = jax.jacfwd(g, has_aux=True)(p, on)
        return v, J, aux

    return jax.jit(jax.vmap(f))


def solve(rows):
    """Values, Jacobians and aux of the (XF, ZF, L, EA, W, CB, on) rows."""
    n = len(rows)
    assert n <= B
    rows = list(rows) + [rows[0]] * (B - n)
    P = jnp.array([r[:6] for r in rows], dtype=jnp.float64)
    on = jnp.array([r[6] for r in rows])
    v, J, aux = _solver()(P, on)
    return np.asarray(v)[:n], np.asarray(J)[:n], [np.asarray(a)[:n] for a in aux]


def moorpy_tensions(case):
    """MoorPy's (HF, VF, HA, VA) in jaxstring's convention. A line free of the seabed
    is given to MoorPy with its anchor 1e6 m above the seabed (CB < 0 means that)."""
    from moorpy.Catenary import catenary as mp_catenary

    XF, ZF, L, EA, W, CB, on = case
    cb = CB if (on and W > 0) else -1e6
    fxa, fza, fxb, fzb, _ = mp_catenary(XF, ZF, L, EA, W, CB=cb, Tol=1e-10, MaxIter=500)
    return np.array([-fxb, -fzb, fxa, fza])


# ---------------------------------------------------------------------------
# MoorPy


def test_against_moorpy():
    pytest.importorskip("moorpy")
    rows = [c for cs in CASES.values() for c in cs]
    v, _, (LB, res, conv) = solve(rows)
    assert conv.all() and np.all(res <= 1e-11 * np.array([r[2] for r in rows]))
    worst = {}
    k = 0
    for name, cs in CASES.items():
        for c in cs:
            ref = moorpy_tensions(c)
            err = np.max(np.abs(v[k] - ref)) / np.max(np.abs(ref))
            worst[name] = max(worst.get(name, 0.0), err)
            k += 1
    print({n: f"{e:.1e}" for n, e in worst.items()})
    for name, err in worst.items():
        assert err < 1e-8, (name, err)
    # the classes are the ones named: contact lays line down, friction lowers HA
    i = {
        n: sum(len(cs) for cs in list(CASES.values())[:j]) for j, n in enumerate(CASES)
    }
    assert LB[i["seabed contact"]] > 100 and v[i["seabed contact"], 3] == 0
    assert v[i["seabed friction"], 2] < 0.9 * v[i["seabed friction"], 0]
    assert v[i["seabed friction"] + 2, 2] == 0  # friction holds the laid length
    assert v[i["bunched"], 0] == 0 and v[i["taut"], 3] > 0


def test_vertical_lines():
    """XF = 0 (MoorPy's ProfileType 6 and 4 formulas, which are exact there; MoorPy
    gives the slack line's VA with the opposite sign, here it pulls the anchor down
    as the suspended-line formula VA = VF - W L says)."""
    W, EA, ZF = 800.0, 1e9, 300.0
    rows = [
        (0.0, ZF, 299.9, EA, W, 0.0, False),
        (0.0, ZF, 310.0, EA, W, 0.0, False),
        (0.0, ZF, 299.9, EA, W, 0.0, True),
        (0.0, ZF, 310.0, EA, W, 0.0, True),
    ]
    v, J, (LB, res, conv) = solve(rows)
    assert conv.all() and np.all(np.isfinite(J))
    # taut: VF = EA (ZF - L - W L^2/(2 EA))/L + W L
    L = 299.9
    T = EA * (ZF - L - W * L**2 / (2 * EA)) / L
    for k in (0, 2):
        np.testing.assert_allclose(v[k], [0, T + W * L, 0, T], rtol=1e-12, atol=1e-9)
    # slack, free of the seabed: folded in two, LB from the lowest point up
    L = 310.0
    Lb = (ZF + L + W * L**2 / (2 * EA)) / (2 + W * L / EA)
    np.testing.assert_allclose(v[1], [0, W * Lb, 0, -W * (L - Lb)], rtol=1e-12)
    # slack on the seabed: L_H hangs, L_H + W L_H^2/(2 EA) = ZF
    LH = math.sqrt(2 * ZF * EA / W + (EA / W) ** 2) - EA / W
    np.testing.assert_allclose(v[3], [0, W * LH, 0, 0], rtol=1e-9)
    assert abs(LB[3] - (L - LH)) < 1e-6


# ---------------------------------------------------------------------------
# Limits


def _brentq(f, a, b):
    from scipy.optimize import brentq

    return brentq(f, a, b, xtol=1e-15, rtol=1e-15, maxiter=500)


def test_inextensible_limit():
    """EA -> inf: the classic catenary. Free hanging: sinh(lam)/lam =
    sqrt(L^2 - ZF^2)/XF, HF = W XF/(2 lam), VF = W (ZF coth(lam) + L)/2. With a
    touchdown (CB = 0, a = HF/W): the suspended length Ls = sqrt(ZF^2 + 2 a ZF)
    spans a asinh(Ls/a), XF = L - Ls + a asinh(Ls/a), VF = W Ls."""
    pytest.importorskip("scipy")
    EA, W = 1e17, 700.0
    free = [(300.0, 100.0, 400.0), (500.0, -120.0, 560.0), (50.0, 300.0, 330.0)]
    touch = [(800.0, 250.0, 902.2), (370.0, 40.0, 400.0)]
    rows = [(X, Z, L, EA, W, 0.0, False) for X, Z, L in free]
    rows += [(X, Z, L, EA, W, 0.0, True) for X, Z, L in touch]
    v, _, _ = solve(rows)
    for k, (X, Z, L) in enumerate(free):
        r = math.sqrt(L * L - Z * Z) / X
        lam = _brentq(lambda t: math.sinh(t) / t - r, 1e-9, 50.0)
        ref = [W * X / (2 * lam), W * (Z / math.tanh(lam) + L) / 2]
        np.testing.assert_allclose(v[k, :2], ref, rtol=1e-9)
    for k, (X, Z, L) in enumerate(touch, start=len(free)):

        def gap(a, X=X, Z=Z, L=L):
            Ls = math.sqrt(Z * Z + 2 * a * Z)
            return L - Ls + a * math.asinh(Ls / a) - X

        a = _brentq(gap, 1e-3, 1e7)
        ref = [W * a, W * math.sqrt(Z * Z + 2 * a * Z)]
        np.testing.assert_allclose(v[k, :2], ref, rtol=1e-9)


def test_weightless_limit():
    """W -> 0: a straight elastic bar, T = EA (d/L - 1) along the chord when taut,
    no tension when slack; W = 0 is answered in closed form, a light line (W small
    against the tension per length) by the Newton solve."""
    EA = 1e8
    rows = [
        (300.0, 400.0, 495.0, EA, 0.0, 0.0, True),
        (300.0, 400.0, 495.0, EA, 1e-6, 0.0, True),
        (300.0, -400.0, 495.0, EA, 1e-6, 0.0, False),
        (300.0, 400.0, 495.0, EA, -1e-6, 0.0, False),
        (300.0, 400.0, 505.0, EA, 0.0, 0.0, True),
    ]
    v, J, (_, _, conv) = solve(rows)
    assert conv.all()
    for k, (X, Z, L, *_) in enumerate(rows[:4]):
        d = math.hypot(X, Z)
        T = EA * (d / L - 1)
        np.testing.assert_allclose(v[k], [T * X / d, T * Z / d] * 2, rtol=1e-7)
    np.testing.assert_array_equal(v[4], 0.0)
    # and the bar's stiffness: EA/L along the chord, T/d across it
    X, Z, L = rows[0][:3]
    d = math.hypot(X, Z)
    e, n = np.array([X, Z]) / d, np.array([-Z, X]) / d
    K = EA / L * np.outer(e, e) + EA * (d / L - 1) / d * np.outer(n, n)
    np.testing.assert_allclose(J[0, :2, :2], K, rtol=1e-12)


# ---------------------------------------------------------------------------
# Derivatives


DERIV_CASES = [
    CASES["seabed contact"][0],
    CASES["seabed friction"][0],
    CASES["seabed friction"][2],
    CASES["taut"][0],
    CASES["free hanging"][0],
    CASES["buoyant"][0],
    CASES["nearly vertical"][1],
    CASES["bunched"][1],
    CASES["flat"][1],
]


def _steps(c):
    """(column, step) of the central differences at case `c`: h = 1e-5 |p| for ZF
    and L (a taut line's stretch is a small part of them), 1e-4 |p| for the others
    (at least 1e-4 m for XF); where p - h stays valid (XF, CB >= 0; ZF = 0 is the
    seabed)."""
    out = []
    for j in range(6):
        h = (1e-5 if j in (1, 2) else 1e-4) * max(abs(c[j]), 1.0)
        if (j in (0, 5) and c[j] - h < 0) or (j == 1 and c[1] == 0):
            continue
        out.append((j, h))
    return out


def test_derivatives_against_central_differences():
    """d(HF, VF, HA, VA)/d(XF, ZF, L, EA, W, CB): the Jacobian (implicit
    differentiation) against central differences at steps h and h/2, Richardson
    extrapolated; within 1e-6 of each column's largest entry."""
    rows = []
    for c in DERIV_CASES:
        for j, h in _steps(c):
            for t in (h, -h, h / 2, -h / 2):
                r = list(c)
                r[j] += t
                rows.append(tuple(r))
    v, _, _ = solve(rows)
    _, J, _ = solve(DERIV_CASES)
    k = 0
    worst = 0.0
    for i, c in enumerate(DERIV_CASES):
        for j, h in _steps(c):
            d1 = (v[k] - v[k + 1]) / (2 * h)
            d2 = (v[k + 2] - v[k + 3]) / h
            fd = (4 * d2 - d1) / 3
            k += 4
            scale = max(np.max(np.abs(J[i, :, j])), 1e-300)
            err = np.max(np.abs(J[i, :, j] - fd)) / scale
            worst = max(worst, err)
            assert err < 1e-6, (c, NAMES[j], J[i, :, j], fd)
    print(f"largest relative derivative error {worst:.1e}")


@functools.cache
def _single():
    """One line, unbatched: values, reverse-mode Jacobian, `catenary_stiffness`,
    and the reverse-mode gradient of the 3-D fairlead force's square through
    `catenary_forces` (fairlead at (0.6 XF, 0.8 XF, ZF) from the origin)."""

    def f(p, on):
        v, pull = jax.vjp(lambda q: _fields(q, on)[0], p)
        Jr = jax.vmap(pull)(jnp.eye(4))[0]  # reverse mode, row by row
        K = catenary_stiffness(*p, on)

        def f2(fair):
            ff, _, _ = catenary_forces(jnp.zeros(3), fair, *p[2:], on)
            return jnp.sum(ff**2)

        g = jax.grad(f2)(jnp.stack([0.6 * p[0], 0.8 * p[0], p[1]]))
        return v, Jr, K, g

    return jax.jit(f)


def test_vmap_equals_loop_and_reverse_mode():
    """A loop of unbatched calls gives vmap's values; reverse mode (jax.jacrev,
    jax.grad) gives the forward-mode Jacobian; catenary_stiffness its (XF, ZF)
    block; no NaN on the vertical."""
    rows = [c for cs in CASES.values() for c in cs[:1]] + [
        (0.0, 300.0, 299.9, 1e9, 800.0, 0.0, False),
        (0.0, 300.0, 310.0, 1e9, 800.0, 0.0, False),
    ]
    v, J, _ = solve(rows)
    for k, r in enumerate(rows):
        vk, Jr, K, g = _single()(jnp.array(r[:6]), r[6])
        np.testing.assert_allclose(vk, v[k], rtol=1e-13, atol=1e-6)
        np.testing.assert_allclose(
            Jr, J[k], rtol=1e-10, atol=1e-10 * np.abs(J[k]).max()
        )
        np.testing.assert_allclose(
            K, J[k, :2, :2], rtol=1e-10, atol=1e-10 * np.abs(J[k]).max()
        )
        assert np.all(np.isfinite(g))


@functools.cache
def _forces3d():
    """Batched: forces on fairlead and anchor (6,) and their Jacobian w.r.t. the
    fairlead position (6, 3)."""

    def f(anchor, fair, L, EA, W, on):
        def g(q):
            ff, fa, _ = catenary_forces(anchor, q, L, EA, W, 0.0, on)
            out = jnp.concatenate([ff, fa])
            return out, out

        return jax.jacfwd(g, has_aux=True)(fair)[::-1]

    return jax.jit(jax.vmap(f))


def forces3d(rows):
    """(anchor, fairlead, L, EA, W, on) rows -> forces (n, 6), Jacobians (n, 6, 3)."""
    n = len(rows)
    rows = list(rows) + [rows[0]] * (16 - n)
    cols = [jnp.array(np.array([r[i] for r in rows], dtype=float)) for i in range(5)]
    on = jnp.array([r[5] for r in rows])
    F, K = _forces3d()(*cols, on)
    return np.asarray(F)[:n], np.asarray(K)[:n]


def test_zero_span_3d():
    """Anchor and fairlead on one vertical: forces and derivatives finite; a taut
    tendon's horizontal stiffness is 1/(dX/dHF), isotropic (against central
    differences), a slack line's zero; off the vertical the 3-D forces are the
    2-D tensions turned into the plane of the line."""
    W, EA = 800.0, 1e9
    anchor = np.array([10.0, -5.0, -320.0])
    up = anchor + [0.0, 0.0, 300.0]
    off = anchor + [600.0, 800.0, 250.0]
    base = [
        (anchor, up, 299.9, EA, W, True),
        (anchor, up, 310.0, EA, W, False),
        (anchor, up, 310.0, EA, W, True),
        (anchor, off, 1100.0, EA, W, True),
    ]
    h = 1e-3
    shifted = [
        (anchor, up + [t, 0, 0], 299.9, EA, W, True) for t in (h, -h, h / 2, -h / 2)
    ]
    F, K = forces3d(base + shifted)
    assert np.all(np.isfinite(F)) and np.all(np.isfinite(K))
    fd = (4 * (F[6] - F[7]) / h - (F[4] - F[5]) / (2 * h)) / 3
    kx = K[0, 0, 0]
    assert kx < 0 and abs(K[0, 1, 1] - kx) < 1e-9 * abs(kx)
    np.testing.assert_allclose(K[0, :, 0], fd, rtol=1e-6, atol=1e-6 * abs(kx))
    v, J, _ = solve([(0.0, 300.0, 299.9, EA, W, 0.0, True)])
    np.testing.assert_allclose(-kx, J[0, 0, 0], rtol=1e-12)  # = dHF/dXF at XF = 0
    np.testing.assert_array_equal(K[1:3, 0:2, 0:2], 0.0)  # slack vertical
    # off the vertical: the 2-D tensions along e_h = (0.6, 0.8)
    v, _, _ = solve([(1000.0, 250.0, 1100.0, EA, W, 0.0, True)])
    HF, VF, HA, VA = v[0]
    eh = np.array([0.6, 0.8])
    np.testing.assert_allclose(F[3], [*(-HF * eh), -VF, *(HA * eh), VA], rtol=1e-12)


def test_profile():
    """The profile starts at the anchor with the anchor tension and ends at the
    fairlead with the fairlead tension; against MoorPy's profile where MoorPy's
    formulas are complete (free hanging; friction on the seabed: MoorPy leaves the
    stretch H_F s/EA out of a frictionless laid length)."""
    mp = pytest.importorskip("moorpy.Catenary")
    rows = [
        CASES["seabed contact"][0],
        CASES["seabed friction"][0],
        CASES["seabed friction"][2],
        CASES["free hanging"][0],
        CASES["buoyant"][0],
        CASES["bunched"][0],
        CASES["flat"][1],
        CASES["nearly vertical"][0],
    ]
    n = 21
    v, _, (LB, res, conv) = solve(rows)

    def prof(p, on, t, LB):
        sol = CatenarySolution(*t, LB, 0.0, True, 0)
        s = jnp.linspace(0.0, p[2], n)
        return catenary_profile(s, *p, on, solution=sol)

    P = jnp.array([r[:6] for r in rows])
    on = jnp.array([r[6] for r in rows])
    x, z, T = jax.jit(jax.vmap(prof))(P, on, jnp.array(v), jnp.array(LB))
    for k, r in enumerate(rows):
        XF, ZF, L = r[:3]
        assert abs(x[k, -1] - XF) < 1e-9 * L and abs(z[k, -1] - ZF) < 1e-9 * L
        assert x[k, 0] == 0 and z[k, 0] == 0
        HF, VF, HA, VA = v[k]
        np.testing.assert_allclose(T[k, -1], math.hypot(HF, VF), rtol=1e-12)
        np.testing.assert_allclose(
            T[k, 0], math.hypot(HA, VA), rtol=1e-12, atol=1e-9 * T[k, -1]
        )
    for k in (1, 2, 3, 4):
        XF, ZF, L, EA, W, CB, on_ = rows[k]
        cb = CB if (on_ and W > 0) else -1e6
        info = mp.catenary(
            XF, ZF, L, EA, W, CB=cb, Tol=1e-10, MaxIter=500, plots=1, nNodes=n
        )[4]
        np.testing.assert_allclose(x[k], info["X"], atol=1e-8 * L)
        np.testing.assert_allclose(z[k], info["Z"], atol=1e-8 * L)
        np.testing.assert_allclose(T[k], info["Te"], rtol=1e-8, atol=1e-8 * T[k, -1])
    # the 3-D points lie in the line's vertical plane
    anchor = jnp.array([1.0, 2.0, -320.0])
    fair = anchor + jnp.array([0.6 * 848.67, 0.8 * 848.67, 250.0])
    sol = CatenarySolution(*v[0], LB[0], 0.0, True, 0)
    pts, T3 = jax.jit(catenary_points)(
        jnp.linspace(0, 902.2, n), anchor, fair, 902.2, EA_OC3, W_OC3, solution=sol
    )
    np.testing.assert_allclose(pts[-1], fair, atol=1e-9 * 902.2)
    np.testing.assert_allclose(
        pts[:, :2] - anchor[:2], np.outer(x[0], [0.6, 0.8]), atol=1e-9 * 902.2
    )
    np.testing.assert_allclose(pts[:, 2] - anchor[2], z[0], atol=1e-9 * 902.2)
    np.testing.assert_allclose(T3, T[0], rtol=1e-12)


# ---------------------------------------------------------------------------
# OC3-Hywind


def test_oc3_hywind():
    """The three lines of lines.txt, fairleads fixed at the deck's positions:
    anchor and fairlead tensions as MoorPy's System gives them for the same deck
    (MoorPy's g = 9.81), within 0.01 % (737.2 / 911.4 kN on line 1)."""
    deck = lines.parse_moordyn(lines.case_path("lines.txt"))
    t = deck.types["main"]
    rho = deck.options["rho"]
    W = (t["w"] - rho * math.pi / 4 * t["d"] ** 2) * 9.81
    pos = {p["id"]: np.array(p["position"], dtype=float) for p in deck.points}
    rows = [
        (pos[ln["a"]], pos[ln["b"]], ln["L"], t["EA"], W, True) for ln in deck.lines
    ]
    F, K = forces3d(rows)
    T_fair = np.linalg.norm(F[:, :3], axis=1) / 1e3
    T_anch = np.linalg.norm(F[:, 3:], axis=1) / 1e3
    np.testing.assert_allclose([T_anch[0], T_fair[0]], [737.2, 911.4], rtol=1e-4)
    # chain on the seabed: no uplift at the anchor
    np.testing.assert_array_equal(F[:, 5], 0.0)
    moorpy = pytest.importorskip("moorpy")
    ms = moorpy.System(file=lines.case_path("lines.txt"))
    ms.initialize()
    ref_a = [np.linalg.norm(ln.fA) / 1e3 for ln in ms.lineList]
    ref_f = [np.linalg.norm(ln.fB) / 1e3 for ln in ms.lineList]
    print("anchor", T_anch, ref_a, "fairlead", T_fair, ref_f)
    np.testing.assert_allclose(T_anch, ref_a, rtol=1e-4)
    np.testing.assert_allclose(T_fair, ref_f, rtol=1e-4)
    # the platform's net horizontal force is along x (the deck is symmetric in y)
    assert abs(F[:, 1].sum()) < 1e-9 * T_fair[0] * 1e3


# ---------------------------------------------------------------------------
# Bad input


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(L=0.0), r"`L` must be a finite number > 0 m; got 0.0"),
        (dict(L=-5.0), r"`L` must be a finite number > 0 m; got -5.0"),
        (dict(EA=0.0), r"`EA` must be a finite number > 0 N; got 0.0"),
        (dict(EA=float("nan")), r"`EA` must be a finite number > 0 N; got nan"),
        (dict(W=float("nan")), r"`W` must be finite .*; got nan"),
        (dict(XF=-1.0), r"`XF` must be a finite number >= 0 m; got -1.0"),
        (dict(ZF=float("inf")), r"`ZF` must be finite .*; got inf"),
        (dict(CB=-0.1), r"`CB` must be a finite number >= 0; got -0.1"),
        (dict(ZF=-10.0), r"`ZF` must be >= 0 m when the anchor lies on the seabed"),
        (dict(XF=np.ones(2)), r"`XF` must be a scalar"),
    ],
)
def test_bad_input(kwargs, match):
    args = dict(XF=800.0, ZF=250.0, L=902.2, EA=EA_OC3, W=W_OC3, CB=0.0)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        catenary(**args)


def test_bad_input_3d_and_traced():
    with pytest.raises(ValueError, match=r"`fairlead` must be of shape \(3,\)"):
        catenary_forces(jnp.zeros(3), jnp.ones(2), 100.0, 1e8, 100.0)
    with pytest.raises(ValueError, match=r"`L` must be a finite number > 0 m"):
        catenary_forces(jnp.zeros(3), jnp.ones(3), -1.0, 1e8, 100.0)
    # traced values cannot raise: no solution gives NaN and converged = False
    rows = [
        (800.0, 250.0, -1.0, EA_OC3, W_OC3, 0.0, True),
        (800.0, -10.0, 902.2, EA_OC3, W_OC3, 0.0, True),
    ]
    v, J, (_, res, conv) = solve(rows)
    assert np.all(np.isnan(v)) and not conv.any() and np.all(np.isnan(res))
