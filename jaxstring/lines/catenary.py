r"""The analytic elastic catenary of one mooring line, with seabed contact.

A line of unstretched length $L$, axial stiffness $EA$ and submerged weight $W$ per
unit length hangs from its anchor (end A) to its fairlead (end B), the fairlead
$X_F \ge 0$ away horizontally and $Z_F$ higher. With $H_F$, $V_F$ the horizontal
and vertical tension at the fairlead, the suspended length $\ell$ of the line ends
at its foot with the vertical tension $V_b = V_F - W \ell$ and spans

- $X = (H_F/W)\,[\operatorname{asinh}(V_F/H_F) - \operatorname{asinh}(V_b/H_F)]
  + H_F \ell/EA$ horizontally,
- $Z = (H_F/W)\,[\sqrt{1 + (V_F/H_F)^2} - \sqrt{1 + (V_b/H_F)^2}]
  + (V_F \ell - W \ell^2/2)/EA$ vertically.

A line free of the seabed has $\ell = L$. A sinking line ($W > 0$) whose anchor
lies on a flat seabed puts $L_B = L - V_F/W$ on the seabed where $V_F < W L$; then
$\ell = V_F/W$, $V_b = 0$, and the laid length, dragged by Coulomb friction
$C_B W$ per length towards the anchor, adds
$L_B + H_F L_B/EA - C_B W/(2 EA)\,[L_B^2 - x_B \max(x_B, 0)]$,
$x_B = L_B - H_F/(C_B W)$,
to $X$ ($x_B$: where the seabed tension reaches zero). The two closure equations
$X(H_F, V_F) = X_F$, $Z(H_F, V_F) = Z_F$ are solved by Newton's method. These are
the equations of Jonkman's quasi-static mooring line (J. M. Jonkman, "Dynamics
modeling and loads analysis of an offshore floating wind turbine", NREL/TP-500-41958,
2007, the mooring-line model of FAST v7), of MoorPy's `catenary` (moorpy/Catenary.py)
and of MAP++ (M. Masciola, J. Jonkman, A. Robertson, "Implementation of a
multisegmented, quasi-static cable model", ISOPE 2013). The initial guess is theirs
(A. H. Peyrot, A. M. Goulois, "Analysis of cable structures", Computers & Structures
10, 1979), plus the straight elastic bar's tension when the chord is longer than the
line.

Cases answered in closed form (no Newton solve): a weightless line (a straight
elastic bar, slack when the chord is shorter than $L$); a line lying flat along the
seabed ($Z_F = 0$, $X_F > L$); and a line with seabed contact too long to reach the
fairlead without slack ($X_F \le L - L_H$, $L_H$ the unstretched length hanging
vertically from the fairlead down to the seabed: MoorPy's "L"-shaped profile): no
horizontal tension, the excess lies bunched on the seabed. A vertical line
($X_F = 0$) is solved with $H_F = 0$ held.

Derivatives are exact: the solve carries a custom JVP by the implicit-function
theorem, $\partial(H_F, V_F)/\partial\theta =
-(\partial r/\partial(H_F, V_F))^{-1} \partial r/\partial\theta$, for
$\theta = (X_F, Z_F, L, EA, W, C_B)$, so that `jax.grad`, `jax.jacfwd`,
`jax.jacrev` and `jax.vmap` all work. The evaluation is branch-free (`jnp.where`
with NaN-safe inputs in the branches not taken), so a batch under `jax.vmap` runs
one loop of Newton iterations.

Sign conventions (Jonkman's and MoorPy's): $H_F \ge 0$ and $V_F$ are the line's
tension at the fairlead, which pulls the fairlead towards the anchor by $H_F$ and
down by $V_F$; $H_A$, $V_A$ are its tension at the anchor, which pulls the anchor
towards the fairlead by $H_A$ and up by $V_A$. Only a line whose anchor lies on
the seabed can touch it (as in MoorPy when the anchor end is at the seabed; a line
hung between two points above the seabed that sags onto it, MoorPy's "U" profile,
is not modelled). The sea surface is not modelled either: a buoyant line
($W < 0$) floats up freely.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Float

from .._arrays import BoolScalar, FloatScalar, IntScalar
from .._geometry import safe_norm
from .._validate import (
    check_finite,
    check_nonnegative,
    check_positive,
    check_shape,
    is_concrete,
    options_of,
    same_signature,
    show,
)


__all__ = [
    "CatenarySolution",
    "catenary",
    "catenary_stiffness",
    "catenary_profile",
    "catenary_forces",
    "catenary_points",
]


class CatenarySolution(eqx.Module):
    r"""The end tensions of one catenary line and the state of its solve.

    **Fields:**

    - `HF`: horizontal tension at the fairlead, N ($\ge 0$; pulls the fairlead
      towards the anchor).
    - `VF`: vertical tension at the fairlead, N (positive pulls the fairlead down).
    - `HA`: horizontal tension at the anchor, N (pulls the anchor towards the
      fairlead; less than `HF` by the seabed friction).
    - `VA`: vertical tension at the anchor, N (positive pulls the anchor up; zero
      where the line touches down on the seabed).
    - `LB`: unstretched length lying on the seabed, m.
    - `residual`: largest closure error of the solved equations, m (0 for the
      closed-form cases, NaN for inputs that have no solution).
    - `converged`: whether `residual` is within the tolerance (relative to $L$).
    - `iterations`: Newton iterations taken (0 for the closed-form cases).
    """

    HF: FloatScalar
    VF: FloatScalar
    HA: FloatScalar
    VA: FloatScalar
    LB: FloatScalar
    residual: FloatScalar
    converged: BoolScalar
    iterations: IntScalar


# ---------------------------------------------------------------------------
# NaN-safe pieces of the closure equations


def _f64(x):
    return jnp.asarray(x, dtype=jnp.float64)


def _safe_sqrt(x):
    """sqrt(x) for x >= 0 whose derivative is finite (zero) at x = 0."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def _asinhc(y):
    """asinh(y)/y, by its series 1 - y^2/6 + 3 y^4/40 near y = 0."""
    small = jnp.abs(y) < 1e-3
    ys = jnp.where(small, 1.0, y)
    y2 = y * y
    return jnp.where(small, 1.0 - y2 / 6.0 + 0.075 * y2 * y2, jnp.arcsinh(ys) / ys)


def _cos_mean(H, p, q):
    r"""$H (\operatorname{asinh}(p/H) - \operatorname{asinh}(q/H))/(p - q)$: the
    mean of $\cos\phi = H/\sqrt{H^2 + v^2}$ over the vertical tension $v$ from $q$
    to $p$ (dimensionless), for $H \ge 0$.

    By $\operatorname{asinh} a - \operatorname{asinh} b = \operatorname{asinh} z$,
    $z = a \sqrt{1 + b^2} - b \sqrt{1 + a^2} = (p T_q - q T_p)/H^2
    = (p^2 - q^2)/(p T_q + q T_p)$, $T_v = \sqrt{H^2 + v^2}$: the last form when $p$,
    $q$ share a sign, the middle one otherwise, so that no digits cancel when
    $p - q = W\ell$ is small against the tensions (a light or highly tensioned
    line), and the value stays finite at $H = 0$ (a vertical line). Also returns
    the mean divided by $H$ (meaningless for $p q \le 0$ at $H = 0$, where it
    is infinite).
    """
    Tp = _safe_sqrt(H * H + p * p)
    Tq = _safe_sqrt(H * H + q * q)
    same = p * q > 0
    dpq = p - q
    # G = z/(p - q)
    den_same = jnp.where(same, p * Tq + q * Tp, 1.0)
    G_same = (p + q) / den_same
    opp_ok = ~same & (H > 0) & (dpq != 0)
    Hs = jnp.where(H > 0, H, 1.0)
    G_opp = (p * Tq - q * Tp) / (Hs * Hs * jnp.where(opp_ok, dpq, 1.0))
    G_opp = jnp.where(dpq == 0, 1.0 / Hs, G_opp)  # p = q = 0: cos = 1
    G = jnp.where(same, G_same, G_opp)
    d_over_H = G * _asinhc(dpq * G)
    # opposite signs at H = 0: H asinh(p/H) -> 0
    return jnp.where(same | (H > 0), H * d_over_H, 0.0), d_over_H


def _sin_mean(H, p, q):
    r"""$(T_p - T_q)/(p - q) = (p + q)/(T_p + T_q)$: the mean of
    $\sin\phi = v/\sqrt{H^2 + v^2}$ over $v$ from $q$ to $p$ (no cancellation)."""
    Tp = _safe_sqrt(H * H + p * p)
    Tq = _safe_sqrt(H * H + q * q)
    den = Tp + Tq
    pos = den > 0
    return jnp.where(pos, (p + q) / jnp.where(pos, den, 1.0), 0.0)


def _seabed_integral(s, HF, LB, cbw):
    r"""$\int_0^s T\,ds'$ along the laid length ($0 \le s \le L_B$), where the
    tension $T = \max(H_F - C_B W (L_B - s'), 0)$ grows from the anchor by the
    friction $C_B W$ per length (Jonkman 2007; MoorPy)."""
    tension_at_anchor = cbw * LB <= HF  # x_B <= 0: no slack stretch at the anchor
    cbw_s = jnp.where(tension_at_anchor, 1.0, cbw)
    xB = LB - HF / cbw_s
    return jnp.where(
        tension_at_anchor,
        HF * s - cbw * (LB * s - 0.5 * s * s),
        0.5 * cbw * jnp.maximum(s - xB, 0.0) ** 2,
    )


def _closure(HF, VF, L, EA, W, CB, contact, jacobian=False):
    r"""The spans (X, Z) reached by a line with fairlead tensions (HF, VF), its
    anchor tensions (HA, VA) and its laid length LB; with `jacobian`, also
    $\partial(X, Z)/\partial(H_F, V_F)$ (2x2). `contact`: the anchor lies on the
    seabed and W > 0.

    The Jacobian is written out (cheaper to compile than automatic
    differentiation, and it keeps the cancellation-free forms). Free of the seabed
    ($\ell = L$, $V_b = V_F - W L$), with $T_F$, $T_b$ the end tensions:

    - $\partial X/\partial H_F = \ell D/H_F - Q + L/EA$,
      $\partial X/\partial V_F = \partial Z/\partial H_F = -H_F \ell E/(T_F T_b)$,
      $\partial Z/\partial V_F = Q + L/EA$,

    with $D$, $E$ the means of `_cos_mean`, `_sin_mean` and
    $Q = (V_F/T_F - V_b/T_b)/W$; on the seabed ($\ell = V_F/W$, $V_b = 0$) the laid
    length $L_B = L - V_F/W$ and its friction add their own terms.
    """
    Va = VF - W * L
    on_bed = contact & (Va < 0)
    Ws = jnp.where(contact, W, 1.0)
    ell = jnp.where(on_bed, VF / Ws, L)  # suspended unstretched length
    LB = L - ell
    Vb = jnp.where(on_bed, 0.0, Va)  # vertical tension at the suspended part's foot
    cbw = CB * W
    D, D_over_H = _cos_mean(HF, VF, Vb)
    E = _sin_mean(HF, VF, Vb)
    X = LB + _seabed_integral(LB, HF, LB, cbw) / EA + ell * D + HF * ell / EA
    Z = ell * E + (Vb * ell + 0.5 * W * ell * ell) / EA
    HA = jnp.where(on_bed, jnp.maximum(HF - cbw * LB, 0.0), HF)
    if not jacobian:
        return X, Z, HA, Vb, LB
    TF = _safe_sqrt(HF * HF + VF * VF)
    Tb = _safe_sqrt(HF * HF + Vb * Vb)
    TT = TF * Tb
    TTs = jnp.where(TT > 0, TT, 1.0)
    # Q = (VF/TF - Vb/Tb)/W = (VF Tb - Vb TF)/(W TF Tb), VF - Vb = W ell: for
    # VF, Vb of one sign rationalised to HF^2 ell (VF + Vb)/(VF Tb + Vb TF)
    same = VF * Vb > 0
    den = jnp.where(same, VF * Tb + Vb * TF, 1.0)
    dV = VF - Vb
    dVs = jnp.where(same | (dV == 0), 1.0, dV)
    num = jnp.where(
        same, HF * HF * ell * (VF + Vb) / den, ell * (VF * Tb - Vb * TF) / dVs
    )
    Q = num / TTs
    cross = -HF * ell * E / TTs  # dX/dVF = dZ/dHF (both are d^2 of one potential)
    # on the seabed: X = LB + I(LB)/EA + (HF/W) asinh(VF/HF) + HF ell/EA,
    # Z = (TF - HF)/W + VF^2/(2 W EA)
    tension_at_anchor = cbw * LB <= HF
    cbw_s = jnp.where(tension_at_anchor, 1.0, cbw)
    dI_dH = jnp.where(tension_at_anchor, LB, HF / cbw_s)
    TFs = jnp.where(TF > 0, TF, 1.0)
    lift = -ell * VF / (TFs * (TF + HF))  # (HF/TF - 1)/W without cancellation
    dX_dV = lift + jnp.where(tension_at_anchor, CB * LB / EA, HF / (Ws * EA))
    J = jnp.where(
        on_bed,
        jnp.stack(
            [
                jnp.stack([ell * D_over_H - ell / TFs + dI_dH / EA + ell / EA, dX_dV]),
                jnp.stack([lift, ell / TFs + ell / EA]),
            ]
        ),
        jnp.stack(
            [
                jnp.stack([ell * D_over_H - Q + L / EA, cross]),
                jnp.stack([cross, Q + L / EA]),
            ]
        ),
    )
    return X, Z, HA, Vb, LB, J


def _initial_guess(XF, ZF, L, EA, W):
    """Peyrot and Goulois's start (Jonkman 2007; MoorPy), plus the straight elastic
    bar's tension when the chord is longer than the line (a taut line's tension is
    mostly elastic, which the weight-only guess misses by orders of magnitude)."""
    d = _safe_sqrt(XF * XF + ZF * ZF)
    taut = L <= d
    XFs = jnp.where(XF > 0, XF, 1.0)
    lam = jnp.where(
        taut, 0.2, jnp.sqrt(jnp.maximum(3.0 * ((L * L - ZF * ZF) / XFs**2 - 1.0), 0.0))
    )
    lam = jnp.where((XF > 0) & (lam > 0), lam, 1.0)
    HF = jnp.abs(0.5 * W * XF / lam)
    VF = 0.5 * (jnp.abs(W) * ZF / jnp.tanh(lam) + W * L)
    T0 = EA * jnp.maximum(d / L - 1.0, 0.0)
    ds = jnp.where(d > 0, d, 1.0)
    HF = HF + T0 * XF / ds
    VF = VF + T0 * ZF / ds
    return jnp.maximum(HF, 1e-10 * jnp.abs(W) * L), VF


def _solve2(J, b):
    """J^{-1} b for a 2x2 J (written out: cheaper than a batched LU under vmap)."""
    det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
    ok = (det != 0) & jnp.isfinite(det)
    dets = jnp.where(ok, det, 1.0)
    out = (
        jnp.stack([J[1, 1] * b[0] - J[0, 1] * b[1], J[0, 0] * b[1] - J[1, 0] * b[0]])
        / dets
    )
    return jnp.where(ok, out, 0.0)


def _newton(xz, p, contact, pin, max_iter):
    """Damped Newton on the closure equations, values only: (HF, VF), the
    iterations taken and the closure error there (m)."""
    XF, ZF = xz[0], xz[1]
    L, EA, W, CB = p[0], p[1], p[2], p[3]
    HF0, VF0 = _initial_guess(XF, ZF, L, EA, W)
    x0 = jnp.stack([jnp.where(pin, 0.0, HF0), VF0])

    def resid(x, jacobian=False):
        out = _closure(x[0], x[1], L, EA, W, CB, contact, jacobian)
        # a vertical line holds HF = 0 (its HF equation is singular there)
        r = jnp.stack([jnp.where(pin, x[0], out[0] - XF), out[1] - ZF])
        if not jacobian:
            return r
        return r, jnp.where(pin, out[-1].at[0].set(jnp.array([1.0, 0.0])), out[-1])

    def merit(r):
        return jnp.max(jnp.abs(r))

    def cond(c):
        return (~c[2]) & (c[1] < max_iter)

    def body(c):
        x, it, _, _ = c
        r, J = resid(x, jacobian=True)
        dx = -_solve2(J, r)
        # Damped Newton (Jonkman's and MoorPy's solvers limit their steps too):
        # stop short of HF <= 0 (and of VF <= 0 with seabed contact, where the
        # suspended length is VF/W), then halve the step until the closure error
        # drops; a full step is taken near the solution (quadratic convergence).
        frac = 0.5
        a_max = jnp.where(
            dx[0] < 0, frac * x[0] / jnp.where(dx[0] < 0, -dx[0], 1.0), 1.0
        )
        a_max = jnp.where(pin, 1.0, a_max)
        a_vf = jnp.where(
            dx[1] < 0, frac * x[1] / jnp.where(dx[1] < 0, -dx[1], 1.0), 1.0
        )
        a_max = jnp.minimum(a_max, jnp.where(contact, a_vf, 1.0))
        a_max = jnp.minimum(a_max, 1.0)
        # trial step lengths a_max 2^-k, k = 0..11, evaluated together: the
        # longest that decreases the closure error enough (Armijo) is taken
        m0 = merit(r)
        alphas = a_max * 0.5 ** jnp.arange(12.0)
        trial = jax.vmap(lambda a: merit(resid(x + a * dx)))(alphas)
        good = (trial <= (1.0 - 1e-4 * alphas) * m0) | (trial <= 1e-14 * L)
        k = jnp.where(jnp.any(good), jnp.argmax(good), 11)
        xn = x + alphas[k] * dx
        step = jnp.max(jnp.abs(xn - x))
        # Newton converges quadratically: once a full step is this small the next
        # error is at round-off, so the iterate just taken is the answer
        done = (step <= 1e-11 * jnp.max(jnp.abs(xn))) | (m0 == 0)
        done = done | ~jnp.all(jnp.isfinite(xn))
        return xn, it + 1, done, trial[k]

    init = (x0, jnp.asarray(0), jnp.asarray(False), jnp.asarray(jnp.inf))
    x, it, _, res = jax.lax.while_loop(cond, body, init)
    return x, it, res


@jax.custom_jvp
def _implicit(xz, p, x, contact, pin):
    """`x` = (HF, VF), the solution of the closure equations at the fairlead's
    span `xz` = (XF, ZF) and the line's `p` = (L, EA, W, CB), carrying the
    implicit derivative: Newton's iteration runs on the values alone, so it is
    traced once however often the solution is differentiated."""
    del xz, p, contact, pin
    return x


def _implicit_jvp(primals, tangents):
    xz, p, x, contact, pin = primals
    dxz, dp = tangents[0], tangents[1]
    # x as a function of (xz, p): differentiating this rule again (second and
    # higher derivatives) differentiates it through this call, not through a
    # new Newton iteration
    x = _implicit(xz, p, x, contact, pin)
    L, EA, W, CB = p[0], p[1], p[2], p[3]
    Jx = _closure(x[0], x[1], L, EA, W, CB, contact, jacobian=True)[-1]
    # the residual (X - XF, Z - ZF)'s change along the tangents; a tangent that
    # is known to be zero (parameters held while positions move) costs nothing
    rt = jnp.zeros(2, x.dtype)
    if not isinstance(dp, SymbolicZero):

        def spans(p):
            X, Z, *_ = _closure(x[0], x[1], p[0], p[1], p[2], p[3], contact)
            return jnp.stack([X, Z])

        rt = rt + jax.jvp(spans, (p,), (dp,))[1]
    if not isinstance(dxz, SymbolicZero):
        rt = rt - dxz
    # A slack vertical line (HF = 0 with the line's lowest point between its
    # ends): X grows like HF log(1/HF), so dX/dHF is infinite and dHF = 0.
    slack_vertical = pin & (x[1] * (x[1] - W * L) <= 0)
    Jx = jnp.where(slack_vertical, Jx.at[0].set(jnp.array([1.0, 0.0])), Jx)
    rt = jnp.where(slack_vertical, rt.at[0].set(0.0), rt)
    # A case answered in closed form feeds this solve a benign stand-in problem
    # (finite coefficients, so that its zero cotangent meets no inf).
    ok = jnp.all(jnp.isfinite(Jx))
    det = Jx[0, 0] * Jx[1, 1] - Jx[0, 1] * Jx[1, 0]
    ok = ok & (det != 0)
    Jx = jnp.where(ok, Jx, jnp.eye(2))
    return x, -_solve2(Jx, rt)


_implicit.defjvp(_implicit_jvp, symbolic_zeros=True)


# ---------------------------------------------------------------------------
# The line


def _check(XF, ZF, L, EA, W, CB, anchor_on_seabed, tol, max_iter):
    for name, v in (
        ("XF", XF),
        ("ZF", ZF),
        ("L", L),
        ("EA", EA),
        ("W", W),
        ("CB", CB),
        ("anchor_on_seabed", anchor_on_seabed),
    ):
        check_shape(name, v, ())
    check_nonnegative("XF", XF, "m")
    check_finite("ZF", ZF)
    check_positive("L", L, "m")
    check_positive("EA", EA, "N")
    check_finite("W", W)
    check_nonnegative("CB", CB)
    check_positive("tol", tol)
    if not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"`max_iter` must be an integer >= 1; got {max_iter!r}.")
    if all(is_concrete(v) for v in (ZF, W, anchor_on_seabed)):
        if bool(np.asarray(anchor_on_seabed)) and float(W) > 0 and float(ZF) < 0:
            raise ValueError(
                "`ZF` must be >= 0 m when the anchor lies on the seabed and the line "
                "sinks (W > 0): the fairlead cannot lie below the seabed; got "
                f"{show(ZF)}."
            )


def _catenary(
    XF, ZF, L, EA, W, CB, anchor_on_seabed, tol, max_iter, with_kH=False, given=None
):
    """The `CatenarySolution`, and (`with_kH`) the limit of HF/XF as XF -> 0 (N/m;
    meaningful where XF = 0).

    `given`: the fairlead tensions (HF, VF), shape (2,), of a line already solved
    at these arguments (its `CatenarySolution`'s), to differentiate the solution
    without solving again (the diagnostics `residual`, `iterations` are then 0).
    """
    contact = anchor_on_seabed & (W > 0)
    # no solution (the concrete checks raise on these; traced, they give NaN)
    bad = (contact & (ZF < 0)) | ~(L > 0) | ~(EA > 0) | ~(XF >= 0) | ~(CB >= 0)
    for v in (XF, ZF, L, EA, W, CB):
        bad = bad | ~jnp.isfinite(v)
    weightless = W == 0
    ok_contact = contact & ~bad
    # unstretched length hanging vertically from the fairlead to the seabed:
    # L_H + W L_H^2/(2 EA) = Z_F, rationalised to keep digits when W Z_F << EA
    ZFc = jnp.where(ok_contact, ZF, 0.0)
    Wc = jnp.where(ok_contact, W, 1.0)
    EAs = jnp.where(bad, 1.0, EA)
    LH = 2.0 * ZFc / (1.0 + jnp.sqrt(1.0 + 2.0 * ZFc * Wc / EAs))
    bunched = ok_contact & (XF <= L - LH)
    flat = ok_contact & ~bunched & (ZF == 0)
    newton = ~(bad | weightless | bunched | flat)

    # Newton solve; a benign suspended stand-in where a closed form answers
    Ls = jnp.where(bad, 1.0, L)
    XFn = jnp.where(newton, XF, 0.6 * Ls)
    ZFn = jnp.where(newton, ZF, 0.6 * Ls)
    Wn = jnp.where(newton, W, 1e-3 * EAs / Ls)
    CBn = jnp.where(newton, CB, 0.0)
    contact_n = contact & newton
    pin = newton & (XF == 0)
    xz = jnp.stack([XFn, ZFn])
    p = jnp.stack([Ls, EAs, Wn, CBn])
    if given is None:
        x, it, res_n = _newton(
            jax.lax.stop_gradient(xz), jax.lax.stop_gradient(p), contact_n, pin,
            max_iter,
        )  # fmt: skip
        it = it.astype(jnp.float64)
    else:
        # the stand-in's start (finite) where no Newton solve answers
        x0 = jnp.stack(_initial_guess(XFn, ZFn, Ls, EAs, Wn))
        x = jnp.where(newton, jnp.asarray(given, jnp.float64), x0)
        it = res_n = jnp.zeros(())
    x = _implicit(xz, p, jax.lax.stop_gradient(x), contact_n, pin)
    HFn, VFn = x[0], x[1]
    # the anchor end from the fairlead tensions (the closure's last three
    # outputs, written out so that derivatives do not trace the closure again)
    on_bed = contact_n & (VFn - Wn * Ls < 0)
    LBn = jnp.where(on_bed, Ls - VFn / jnp.where(contact_n, Wn, 1.0), 0.0)
    VAn = jnp.where(on_bed, 0.0, VFn - Wn * Ls)
    HAn = jnp.where(on_bed, jnp.maximum(HFn - CBn * Wn * LBn, 0.0), HFn)
    res_n = jax.lax.stop_gradient(res_n)
    if with_kH:
        # On the vertical (HF = 0) dZ/dHF = 0, so dHF/dXF = 1/(dX/dHF): the limit
        # of HF/XF, which gives the horizontal stiffness of a vertical line; zero
        # for a slack vertical line, whose dX/dHF is infinite (X ~ HF log(1/HF)).
        # A vertical line (solved by Newton) hangs free of the seabed, and at
        # HF = 0, dX/dHF = L (D/HF + 1/EA) (`_closure`, Q = 0).
        Vb = VFn - Wn * Ls
        dXdH = Ls * (_cos_mean(jnp.zeros_like(VFn), VFn, Vb)[1] + 1.0 / EAs)
        taut_vertical = pin & (VFn * Vb > 0) & (dXdH > 0)
        kHn = jnp.where(taut_vertical, 1.0 / jnp.where(taut_vertical, dXdH, 1.0), 0.0)
    else:
        kHn = jnp.zeros_like(HFn)

    # weightless: a straight elastic bar, T = EA max(d/L - 1, 0)
    d = _safe_sqrt(XF * XF + ZF * ZF)
    ds = jnp.where(d > 0, d, 1.0)
    T = EAs * jnp.maximum(d / Ls - 1.0, 0.0)
    HFw, VFw = T * XF / ds, T * ZF / ds

    # flat on the seabed, stretched (Z_F = 0, X_F > L): Jonkman 2007, MoorPy
    cbw = CB * W
    HF1 = EAs * (XF / Ls - 1.0) + 0.5 * cbw * Ls  # tension reaches the anchor
    reaches = HF1 >= cbw * Ls
    arg = jnp.where(flat & ~reaches, 2.0 * EAs * cbw * (XF - Ls), 1.0)
    HFf = jnp.where(reaches, HF1, jnp.sqrt(arg))  # else: slack near the anchor
    HAf = jnp.maximum(HFf - cbw * Ls, 0.0)

    # the answer of the case each line is in: one selection of the stacked
    # (HF, VF, HA, VA, LB, kH) per case
    zero = jnp.zeros_like(HFn)
    v = jnp.stack([HFn, VFn, HAn, VAn, LBn, kHn])
    v = jnp.where(weightless, jnp.stack([HFw, VFw, HFw, VFw, zero, T / ds]), v)
    v = jnp.where(bunched, jnp.stack([zero, W * LH, zero, zero, Ls - LH, zero]), v)
    v = jnp.where(flat, jnp.stack([HFf, zero, HAf, zero, Ls, zero]), v)
    v = jnp.where(bad, jnp.nan, v)
    HF, VF, HA, VA, LB, kH = v
    residual = jnp.where(bad, jnp.nan, jnp.where(newton, res_n, 0.0))
    converged = jnp.where(newton, (res_n <= tol * Ls) & jnp.isfinite(HF + VF), ~bad)
    iterations = jnp.where(newton, it, 0.0).astype(jnp.int32)
    return CatenarySolution(HF, VF, HA, VA, LB, residual, converged, iterations), kH


def catenary(
    XF,
    ZF,
    L,
    EA,
    W,
    CB=0.0,
    anchor_on_seabed=True,
    *,
    tol: float = 1e-9,
    max_iter: int = 100,
) -> CatenarySolution:
    r"""Solve the elastic catenary of one line for its end tensions.

    The closure equations (module docstring; Jonkman 2007, NREL/TP-500-41958;
    MoorPy's `catenary`; MAP++) are solved for $(H_F, V_F)$ by Newton's method
    from Peyrot and Goulois's start, or in closed form for a weightless line, a
    line flat on the seabed and a slack line bunched on the seabed. Every case a
    line can be in has an answer: taut (with finite $EA$ a line stretches as far
    as it is pulled), slack and fully suspended, partly on the seabed with or
    without friction, vertical ($X_F = 0$), buoyant ($W < 0$, never on the seabed).
    A solve that does not converge says so in `converged`; inputs without a
    solution give NaN and `converged = False` (and raise, when concrete).

    Derivatives with respect to every argument are exact (implicit-function
    theorem); `jax.vmap` batches lines.

    **Arguments:**

    - `XF`: horizontal distance from the anchor to the fairlead, m, scalar $\ge 0$.
    - `ZF`: height of the fairlead above the anchor, m, scalar (negative only for a
      line free of the seabed).
    - `L`: unstretched length, m, scalar $> 0$.
    - `EA`: axial stiffness, N, scalar $> 0$.
    - `W`: submerged weight per length, N/m, scalar: weight less buoyancy, e.g.
      $(m - \rho_w \pi d^2/4) g$ (negative for a buoyant line; 0 for a
      weightless bar).
    - `CB`: seabed friction coefficient, scalar $\ge 0$ (0: the laid length
      slides freely). MoorPy's negative `CB` (the anchor's height above the
      seabed) is `anchor_on_seabed=False` here.
    - `anchor_on_seabed`: whether the anchor lies on a flat seabed, so that the line
      can rest on it (bool). False: the line is free of any seabed.
    - `tol`: the closure error, relative to $L$, below which `converged` is True.
    - `max_iter`: most Newton iterations.

    **Returns:** a `CatenarySolution`: `HF`, `VF` (fairlead), `HA`, `VA` (anchor)
    tensions in N, the laid length `LB` in m, and `residual`, `converged`,
    `iterations`.

    **Raises:** `ValueError` naming the argument, its value and the valid range when
    a concrete argument is out of range or not finite.
    """
    _check(XF, ZF, L, EA, W, CB, anchor_on_seabed, tol, max_iter)
    on = jnp.asarray(anchor_on_seabed, dtype=bool)
    args = map(_f64, (XF, ZF, L, EA, W, CB))
    return _catenary(*args, on, tol, int(max_iter))[0]


def catenary_stiffness(
    XF, ZF, L, EA, W, CB=0.0, anchor_on_seabed=True, *, tol=1e-9, max_iter=100
) -> Float[Array, "2 2"]:
    r"""Differentiate the fairlead tensions with respect to the fairlead's position.

    $K = \partial(H_F, V_F)/\partial(X_F, Z_F)$, exact (implicit-function
    theorem on the closure equations; MoorPy's `stiffnessB`, which it obtains by
    inverting the same Jacobian). The force on the fairlead is $(-H_F, -V_F)$ in
    the (horizontal, vertical) frame, so its stiffness is $-K$. Where the tension
    is not differentiable (touchdown at the anchor, $Z_F = 0$, the onset of
    bunching) the derivative of the branch in force is returned.

    **Arguments:** as `catenary`.

    **Returns:** `K`, shape (2, 2), N/m: rows $(H_F, V_F)$, columns $(X_F, Z_F)$.
    """
    _check(XF, ZF, L, EA, W, CB, anchor_on_seabed, tol, max_iter)

    on = jnp.asarray(anchor_on_seabed, dtype=bool)
    rest = (*map(_f64, (L, EA, W, CB)), on, tol, int(max_iter))

    def f(xz):
        s = _catenary(xz[0], xz[1], *rest)[0]
        return jnp.stack([s.HF, s.VF])

    return jax.jacfwd(f)(jnp.stack([_f64(XF), _f64(ZF)]))


def catenary_profile(
    s,
    XF,
    ZF,
    L,
    EA,
    W,
    CB=0.0,
    anchor_on_seabed=True,
    *,
    solution: CatenarySolution | None = None,
    tol=1e-9,
    max_iter=100,
):
    r"""Evaluate the line's shape and tension along its unstretched length.

    With the solved tensions, the point at unstretched arc length $s$ from the
    anchor lies at (Jonkman 2007; MoorPy's `catenary` profile):

    - on the seabed ($s \le L_B$): $x = s + \int_0^s T\,ds'/EA$, $z = 0$,
      $T = \max(H_F - C_B W (L_B - s), 0)$ (MoorPy leaves out the stretch
      $H_F s/EA$ of a frictionless laid length; here it is kept, so that the
      profile ends at the fairlead);
    - suspended, $u = s - L_B$ above the foot where the vertical tension is $V_b$,
      $V = V_b + W u$: $x = x(L_B) + H_F/W\,[\operatorname{asinh}(V/H_F) -
      \operatorname{asinh}(V_b/H_F)] + H_F u/EA$, $z = (T - T_b)/W + (V_b u +
      W u^2/2)/EA$, $T = \sqrt{H_F^2 + V^2}$.

    A line bunched on the seabed lies straight to below the fairlead and heaps the
    rest there ($x = \min(s, X_F)$); a weightless line is straight.

    **Arguments:**

    - `s`: unstretched arc lengths from the anchor, m, any shape, in $[0, L]$.
    - `XF` ... `anchor_on_seabed`, `tol`, `max_iter`: as `catenary`.
    - `solution`: the `CatenarySolution` of these arguments, if already solved.

    **Returns:** `(x, z, T)`, each of the shape of `s`: horizontal distance from
    the anchor towards the fairlead and height above the anchor, m, and the
    effective tension, N.
    """
    if solution is None:
        solution = catenary(
            XF, ZF, L, EA, W, CB, anchor_on_seabed, tol=tol, max_iter=max_iter
        )
    s = _f64(s)
    XF, ZF, L, EA, W, CB = map(_f64, (XF, ZF, L, EA, W, CB))
    HF, VF, LB = solution.HF, solution.VF, solution.LB
    on = LB > 0
    Vb = jnp.where(on, 0.0, VF - W * L)
    cbw = CB * W
    sb = jnp.clip(s, 0.0, LB)  # the part of s lying on the seabed
    x_bed = jnp.minimum(sb + _seabed_integral(sb, HF, LB, cbw) / EA, XF)
    u = jnp.maximum(s - LB, 0.0)
    V = Vb + W * u
    x = x_bed + u * _cos_mean(HF, V, Vb)[0] + HF * u / EA
    z = u * _sin_mean(HF, V, Vb) + (Vb * u + 0.5 * W * u * u) / EA
    T_bed = jnp.maximum(HF - cbw * (LB - sb), 0.0)
    T = jnp.where(on & (s <= LB), T_bed, _safe_sqrt(HF * HF + V * V))
    weightless = W == 0
    x = jnp.where(weightless, s * XF / L, x)
    z = jnp.where(weightless, s * ZF / L, z)
    T = jnp.where(weightless, _safe_sqrt(HF * HF + VF * VF), T)
    return x, z, T


def _frame(anchor, fairlead):
    """Horizontal offset (2,), its length XF (NaN-safe at 0) and the height ZF."""
    d = fairlead - anchor
    dh = d[:2]
    return dh, safe_norm(dh), d[2]


def _check3(anchor, fairlead):
    check_shape("anchor", anchor, (3,), "m")
    check_shape("fairlead", fairlead, (3,), "m")
    check_finite("anchor", anchor)
    check_finite("fairlead", fairlead)


def catenary_forces(
    anchor,
    fairlead,
    L,
    EA,
    W,
    CB=0.0,
    anchor_on_seabed=True,
    *,
    tol=1e-9,
    max_iter=100,
):
    r"""Compute the forces one catenary line applies to its fairlead and its anchor.

    The line lies in the vertical plane through its ends ($z$ up); with $e_h$ the
    horizontal unit vector from the anchor towards the fairlead, the fairlead feels
    $(-H_F e_h, -V_F)$ and the anchor $(H_A e_h, V_A)$ (Jonkman 2007; MoorPy's
    sign convention). At zero horizontal span the direction $e_h$ is undefined
    and $H_F = 0$: the horizontal force is written as $-(H_F/X_F)\,\Delta x_h$,
    with $H_F/X_F$ replaced at $X_F = 0$ by its limit $\partial H_F/\partial X_F
    = 1/(\partial X/\partial H_F)$ (zero for a slack vertical line),
    so that the force, and its derivative (the horizontal stiffness of a vertical
    tendon), are finite and exact there.

    **Arguments:**

    - `anchor`: anchor position, m, shape (3,).
    - `fairlead`: fairlead position, m, shape (3,) (above the anchor when the anchor
      lies on the seabed and the line sinks).
    - `L`, `EA`, `W`, `CB`, `anchor_on_seabed`, `tol`, `max_iter`: as `catenary`.

    **Returns:** `(f_fairlead, f_anchor, solution)`: the forces on the fairlead and
    on the anchor, N, shape (3,) each, and the `CatenarySolution`.
    """
    _check3(anchor, fairlead)
    anchor, fairlead = _f64(anchor), _f64(fairlead)
    _, XF, ZF = _frame(anchor, fairlead)
    _check(XF, ZF, L, EA, W, CB, anchor_on_seabed, tol, max_iter)
    on = jnp.asarray(anchor_on_seabed, dtype=bool)
    return _forces(anchor, fairlead, *map(_f64, (L, EA, W, CB)), on, tol, max_iter)


def _forces(anchor, fairlead, L, EA, W, CB, on, tol, max_iter, given=None):
    """`catenary_forces` without the checks; `given` as for `_catenary`."""
    dh, XF, ZF = _frame(anchor, fairlead)
    rest = (L, EA, W, CB, on, tol, int(max_iter))
    sol, kH = _catenary(XF, ZF, *rest, with_kH=True, given=given)
    pos = XF > 0
    XFs = jnp.where(pos, XF, 1.0)
    kF = jnp.where(pos, sol.HF / XFs, kH)  # HF/XF, its limit on the vertical
    kA = jnp.where(pos, sol.HA / XFs, kH)  # where HA = HF
    f_fairlead = jnp.concatenate([-kF * dh, -sol.VF[None]])
    f_anchor = jnp.concatenate([kA * dh, sol.VA[None]])
    return f_fairlead, f_anchor, sol


def catenary_points(s, anchor, fairlead, L, EA, W, **options):
    """Place the points of a catenary line in 3-D, with the tension along it.

    `catenary_profile` in the vertical plane through the line's ends, $z$ up.

    **Arguments:**

    - `s`: unstretched arc lengths from the anchor, m, shape (n,), in $[0, L]$.
    - `anchor`, `fairlead`: end positions, m, shape (3,) each.
    - `L`, `EA`, `W` and the options `CB`, `anchor_on_seabed`, `solution`, `tol`,
      `max_iter`: as `catenary_profile`.

    **Returns:** `(points, T)`: positions, m, shape (n, 3), and effective tension,
    N, shape (n,).
    """
    options = options_of(catenary_profile, "catenary_points", options, skip=6)
    _check3(anchor, fairlead)
    anchor, fairlead = _f64(anchor), _f64(fairlead)
    dh, XF, ZF = _frame(anchor, fairlead)
    x, z, T = catenary_profile(s, XF, ZF, L, EA, W, **options)
    pos = XF > 0
    eh = jnp.where(pos, dh / jnp.where(pos, XF, 1.0), 0.0)
    pts = anchor + x[..., None] * jnp.concatenate([eh, jnp.zeros(1)])
    pts = pts + z[..., None] * jnp.array([0.0, 0.0, 1.0])
    return pts, T


same_signature(catenary_points, catenary_profile, skip=6)
