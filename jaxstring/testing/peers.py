"""Peers of the string pendulum and the tether, used by the tests and the benchmarks:
the equations in NumPy/numba, integrated by CVODE (SUNDIALS, through scikit-sundae)
and scipy's solve_ivp. They need the bench extra: ``pip install ".[bench]"``.

An independent implementation of the equations (nothing here calls into jaxstring;
tests/test_peers.py checks every right-hand side against jaxstring's vector field):

* the string pendulum of Poth et al. (specs/string_pendulum.md) in 2D, in
  displacement variables (eqs 11-14: node positions and velocities, the end node
  carries the end mass), natural variables (eps, t) (eqs 15-23, Cartesian tangent,
  the |t| = 1 constraint through its second derivative) and (eps, phi) (tangent
  angle phi from the downward vertical); gravity g along -y, Kelvin-Voigt damping
  N = EA (eps + alpha eps'), and optionally the tension-only law
  N = max(N, 0) where eps > 0, N = 0 where eps <= 0 (applied after the damping);
* the tether of Blintsov (2017) with lumped masses and linear springs on every link
  (the "lms" method: T = (k_s (l - L_link) + c_s l')/L_link), a fixed root, a
  running end on a piecewise-linear path, weight, buoyancy and quadratic drag in a
  uniform current, added mass in the element inertia.

States are node-major, as in jaxstring (one row per node, flattened row by row), so
the Jacobians are banded: half-bandwidth 7 (pendulum in displacement or (eps, phi)
variables), 11 ((eps, t) and the tether).

Right-hand sides are numba-compiled (``cache=True``). ``cvode_solve`` runs CVODE BDF
with the band linear solver and (a) the analytic banded Jacobian where one is
written (displacement variables, `jac="analytic"`) or (b) CVODE's own banded
difference-quotient Jacobian (`jac="dq"`). ``scipy_solve`` runs solve_ivp (BDF,
Radau, LSODA) on the same compiled functions, with the analytic Jacobian (sparse,
or LSODA's packed band) or the band pattern for scipy's finite differences.

Use::

    peer = make_rhs("displacement", k=40, EA=1e6, alpha=0.01)
    out = cvode_solve(peer, ts, peer.initial_state(np.pi / 2), rtol=1e-8, atol=1e-8)
    end = peer.end_mass(out["ys"])  # (T, 2) end-mass positions, m

numba (imported with this module) and scikit-sundae are in the `bench` extra.
"""

import dataclasses
import math

import numba
import numpy as np


FORMULATIONS = ("displacement", "natural", "angle")
# Gravity (m/s^2) and the tether paper's water density (Table 1, kg/m^3).
G = 9.81
RHO_TABLE1 = 1024.0

_jit = numba.njit(cache=True, fastmath=False)


# ---------------------------------------------------------------------------
# Tension law (shared by the three pendulum formulations)


@_jit
def _law(eps, eps_dot, EA, alpha, slack):
    """Axial force N (N) and its partial derivatives dN/d eps, dN/d eps'."""
    N = EA * (eps + alpha * eps_dot)
    if slack and (eps <= 0.0 or N < 0.0):
        return 0.0, 0.0, 0.0
    return N, EA, EA * alpha


# ---------------------------------------------------------------------------
# Displacement variables: row i-1 = (x_i, y_i, x_i', y_i') for nodes i = 1..k


@_jit
def _disp_elements(y, k, l):
    """Element rows d = D+ r and dv = D+ r' (element e joins nodes e and e + 1)."""
    h = l / k
    d = np.empty((k, 2))
    dv = np.empty((k, 2))
    for e in range(k):
        for a in range(2):
            r1 = y[4 * e + a]
            v1 = y[4 * e + 2 + a]
            r0 = y[4 * (e - 1) + a] if e > 0 else 0.0
            v0 = y[4 * (e - 1) + 2 + a] if e > 0 else 0.0
            d[e, a] = (r1 - r0) / h
            dv[e, a] = (v1 - v0) / h
    return d, dv


@_jit
def _disp_rhs(t, y, out, k, EA, alpha, l, mu, m_s, g, slack):
    d, dv = _disp_elements(y, k, l)
    F = np.zeros((k + 1, 2))  # F[e] = N_e t_e; F[k] = 0 (nothing past the end)
    for e in range(k):
        s = math.sqrt(d[e, 0] ** 2 + d[e, 1] ** 2)
        if s <= 0.0:
            s = 1.0
        tx, ty = d[e, 0] / s, d[e, 1] / s
        eps = s - 1.0
        eps_dot = dv[e, 0] * tx + dv[e, 1] * ty
        N = _law(eps, eps_dot, EA, alpha, slack)[0]
        F[e, 0] = N * tx
        F[e, 1] = N * ty
    c_line = k / (mu * l)
    for j in range(1, k + 1):  # node j, row j - 1
        c = c_line if j < k else 1.0 / m_s
        row = 4 * (j - 1)
        out[row] = y[row + 2]
        out[row + 1] = y[row + 3]
        out[row + 2] = c * (F[j, 0] - F[j - 1, 0])
        out[row + 3] = c * (F[j, 1] - F[j - 1, 1]) - g


@_jit
def _disp_jac(t, y, JJ, k, EA, alpha, l, mu, m_s, g, slack):
    """The exact Jacobian of `_disp_rhs` written into the band of the dense `JJ`."""
    n = 4 * k
    for i in range(n):
        for j in range(max(0, i - 7), min(n, i + 8)):
            JJ[i, j] = 0.0
    h = l / k
    d, dv = _disp_elements(y, k, l)
    # A[e] = dF_e/dd, B[e] = dF_e/d(dv), each divided by h (dd/dr = 1/h).
    A = np.zeros((k + 1, 2, 2))
    B = np.zeros((k + 1, 2, 2))
    for e in range(k):
        s = math.sqrt(d[e, 0] ** 2 + d[e, 1] ** 2)
        if s <= 0.0:
            s = 1.0
        t = (d[e, 0] / s, d[e, 1] / s)
        eps = s - 1.0
        eps_dot = dv[e, 0] * t[0] + dv[e, 1] * t[1]
        N, N_eps, N_rate = _law(eps, eps_dot, EA, alpha, slack)
        for a in range(2):
            for b in range(2):
                tt = t[a] * t[b]
                eye = 1.0 if a == b else 0.0
                # F = N t, eps = |d| - 1, t = d/|d|, eps' = dv . t:
                # dt/dd = (I - t t^T)/|d|, d eps'/dd = (dv - eps' t)/|d|.
                w = dv[e, b] - eps_dot * t[b]
                A[e, a, b] = (
                    N_eps * tt + N / s * (eye - tt) + N_rate / s * t[a] * w
                ) / h
                B[e, a, b] = N_rate * tt / h
    for j in range(1, k + 1):
        c = k / (mu * l) if j < k else 1.0 / m_s
        row = 4 * (j - 1)
        JJ[row, row + 2] = 1.0
        JJ[row + 1, row + 3] = 1.0
        # acc_j = c (F_j - F_(j-1)); F_e depends on (r, v) of nodes e and e + 1.
        for a in range(2):
            for b in range(2):
                col = 4 * (j - 1)
                JJ[row + 2 + a, col + b] = -c * (A[j, a, b] + A[j - 1, a, b])
                JJ[row + 2 + a, col + 2 + b] = -c * (B[j, a, b] + B[j - 1, a, b])
                if j < k:
                    JJ[row + 2 + a, col + 4 + b] = c * A[j, a, b]
                    JJ[row + 2 + a, col + 6 + b] = c * B[j, a, b]
                if j > 1:
                    JJ[row + 2 + a, col - 4 + b] = c * A[j - 1, a, b]
                    JJ[row + 2 + a, col - 2 + b] = c * B[j - 1, a, b]


@_jit
def _disp_end(ys, k):
    return ys[:, 4 * (k - 1) : 4 * (k - 1) + 2].copy()


# ---------------------------------------------------------------------------
# Natural variables: x_i = [(1 + eps_i) t_i]'' from the tridiagonal inverse mass


@_jit
def _natural_x(tx, ty, N, k, l, mu, m_s, g):
    """x = -M^-1 z with z_i = (N_i t_i - F_i)/mu, F_i the weight of the string
    below s_i plus the end mass: (mu (l - s_i) + m_s) g along -y (eqs 15-19).

    M^-1 (eq 17) is (k/l)^2 tridiag(-1, 2, -1) with first row (2, -2) and last row
    (-2, 2 (1 + 1/a)), a = k m_s/(mu l) (the exact inverse of the paper's M)."""
    zx = np.empty(k + 1)
    zy = np.empty(k + 1)
    h = l / k
    for i in range(k + 1):
        below = mu * (l - i * h) + m_s
        zx[i] = N[i] * tx[i] / mu
        zy[i] = (N[i] * ty[i] + below * g) / mu
    c = (k / l) ** 2
    a = k * m_s / (mu * l)
    xx = np.empty(k + 1)
    xy = np.empty(k + 1)
    xx[0] = -c * (2 * zx[0] - 2 * zx[1])
    xy[0] = -c * (2 * zy[0] - 2 * zy[1])
    for i in range(1, k):
        xx[i] = -c * (-zx[i - 1] + 2 * zx[i] - zx[i + 1])
        xy[i] = -c * (-zy[i - 1] + 2 * zy[i] - zy[i + 1])
    xx[k] = -c * (-2 * zx[k - 1] + 2 * (1 + 1 / a) * zx[k])
    xy[k] = -c * (-2 * zy[k - 1] + 2 * (1 + 1 / a) * zy[k])
    return xx, xy


@_jit
def _angle_rhs(t, y, out, k, EA, alpha, l, mu, m_s, g, slack):
    """Row i = (eps, phi, eps', phi'); t = (sin phi, -cos phi), n = (cos phi, sin phi)
    (the tangent angle phi from the downward vertical)."""
    n = k + 1
    tx = np.empty(n)
    ty = np.empty(n)
    N = np.empty(n)
    for i in range(n):
        tx[i] = math.sin(y[4 * i + 1])
        ty[i] = -math.cos(y[4 * i + 1])
        N[i] = _law(y[4 * i], y[4 * i + 2], EA, alpha, slack)[0]
    xx, xy = _natural_x(tx, ty, N, k, l, mu, m_s, g)
    for i in range(n):
        eps, eps_dot, phi_dot = y[4 * i], y[4 * i + 2], y[4 * i + 3]
        # eps'' - (1 + eps) phi'^2 = x . t;  (1 + eps) phi'' + 2 eps' phi' = x . n
        out[4 * i] = eps_dot
        out[4 * i + 1] = phi_dot
        out[4 * i + 2] = xx[i] * tx[i] + xy[i] * ty[i] + (1 + eps) * phi_dot**2
        xn = -xx[i] * ty[i] + xy[i] * tx[i]  # n = (cos, sin) = (-t_y, t_x)
        out[4 * i + 3] = (xn - 2 * eps_dot * phi_dot) / (1 + eps)


@_jit
def _tangent_rhs(t, y, out, k, EA, alpha, l, mu, m_s, g, slack):
    """Row i = (eps, tx, ty, eps', tx', ty'); solves (1 + eps) t'' + eps'' t =
    x - 2 eps' t' and t . t'' = -|t'|^2 for (eps'', t'') at any |t| (eq 22)."""
    n = k + 1
    tx = np.empty(n)
    ty = np.empty(n)
    N = np.empty(n)
    for i in range(n):
        tx[i] = y[6 * i + 1]
        ty[i] = y[6 * i + 2]
        N[i] = _law(y[6 * i], y[6 * i + 3], EA, alpha, slack)[0]
    xx, xy = _natural_x(tx, ty, N, k, l, mu, m_s, g)
    for i in range(n):
        r = 6 * i
        eps, eps_dot, dtx, dty = y[r], y[r + 3], y[r + 4], y[r + 5]
        b1x = xx[i] - 2 * eps_dot * dtx
        b1y = xy[i] - 2 * eps_dot * dty
        b2 = -(dtx * dtx + dty * dty)
        tt = tx[i] ** 2 + ty[i] ** 2
        eps_dd = (tx[i] * b1x + ty[i] * b1y - (1 + eps) * b2) / tt
        out[r] = eps_dot
        out[r + 1] = dtx
        out[r + 2] = dty
        out[r + 3] = eps_dd
        out[r + 4] = (b1x - eps_dd * tx[i]) / (1 + eps)
        out[r + 5] = (b1y - eps_dd * ty[i]) / (1 + eps)


@_jit
def _natural_end(ys, k, l, width, angle):
    """End-mass position: the trapezoid rule of (1 + eps) t over the nodes."""
    h = l / k
    out = np.zeros((ys.shape[0], 2))
    for m in range(ys.shape[0]):
        for i in range(k + 1):
            w = 0.5 * h if (i == 0 or i == k) else h
            eps = ys[m, width * i]
            if angle:
                tx = math.sin(ys[m, width * i + 1])
                ty = -math.cos(ys[m, width * i + 1])
            else:
                tx, ty = ys[m, width * i + 1], ys[m, width * i + 2]
            out[m, 0] += w * (1 + eps) * tx
            out[m, 1] += w * (1 + eps) * ty
    return out


# ---------------------------------------------------------------------------
# The tether: lumped masses and linear springs; row n = (p_n, v_n) of element n


@_jit
def _path(t, times, path):
    """Position and velocity of a piecewise-linear path at time t (constant outside
    the knots; the velocity is the slope of the segment holding t)."""
    K = times.shape[0]
    i = np.searchsorted(times, t, side="right") - 1
    i = min(max(i, 0), K - 2)
    tc = min(max(t, times[0]), times[K - 1])
    inside = times[0] <= t < times[K - 1]
    pos = np.empty(3)
    vel = np.empty(3)
    for a in range(3):
        slope = (path[i + 1, a] - path[i, a]) / (times[i + 1] - times[i])
        pos[a] = path[i, a] + slope * (tc - times[i])
        vel[a] = slope if inside else 0.0
    return pos, vel


@_jit
def _tether_rhs(t, y, out, N, L_link, inertia, k_s, c_s, f_z, half, c_t, c_n, c_l,
                current, root, times, path):  # fmt: skip
    """Element n between links n and n + 1 of the chain root, p_0..p_(N-1), fast:
    mu a_n = T_(n+1) u_(n+1) - T_n u_n + F_n, T_j = (k_s (l_j - L_link) + c_s l_j')
    / L_link, F_n = f_z e_z + drag on v_n - current with the axis i_n = u_(n+1)."""
    fpos, fvel = _path(t, times, path)
    X = np.empty((N + 2, 3))
    XV = np.empty((N + 2, 3))
    for a in range(3):
        X[0, a] = root[a]
        XV[0, a] = 0.0
        X[N + 1, a] = fpos[a]
        XV[N + 1, a] = fvel[a]
        for n in range(N):
            X[n + 1, a] = y[6 * n + a]
            XV[n + 1, a] = y[6 * n + 3 + a]
    Tu = np.empty((N + 1, 3))
    u = np.empty((N + 1, 3))
    for j in range(N + 1):
        dx = X[j + 1] - X[j]
        lj = math.sqrt(dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2)
        s = lj if lj > 0.0 else 1.0
        ldot = 0.0
        for a in range(3):
            u[j, a] = dx[a] / s
            ldot += u[j, a] * (XV[j + 1, a] - XV[j, a])
        T = (k_s * (lj - L_link) + c_s * ldot) / L_link
        for a in range(3):
            Tu[j, a] = T * u[j, a]
    for n in range(N):
        i = u[n + 1]
        vf = np.empty(3)
        for a in range(3):
            vf[a] = y[6 * n + 3 + a] - current[a]
        v_t = vf[0] * i[0] + vf[1] * i[1] + vf[2] * i[2]
        perp = vf - v_t * i
        v_n = math.sqrt(perp[0] ** 2 + perp[1] ** 2 + perp[2] ** 2)
        cross = np.array(
            [i[1] * vf[2] - i[2] * vf[1], i[2] * vf[0] - i[0] * vf[2],
             i[0] * vf[1] - i[1] * vf[0]]
        )  # fmt: skip
        for a in range(3):
            drag = -half * (
                math.pi * c_t * v_t * abs(v_t) * i[a]
                + c_n * v_n * perp[a]
                + c_l * v_t * cross[a]
            )
            F = drag + (f_z if a == 2 else 0.0)
            out[6 * n + a] = y[6 * n + 3 + a]
            out[6 * n + 3 + a] = (Tu[n + 1, a] - Tu[n, a] + F) / inertia


# ---------------------------------------------------------------------------
# The peer object


@dataclasses.dataclass(frozen=True)
class Peer:
    """A compiled right-hand side on flat float64 vectors and what a solver needs.

    `rhs(t, y, yp)` writes dy/dt into `yp` (CVODE's signature); `f(t, y)` returns it;
    `jac(t, y, JJ)` writes the exact Jacobian into the band of a dense `(n, n)`
    `JJ` (None where none is written); `lband`, `uband` the half-bandwidths;
    `end_mass(ys)` maps states `(T, n)` to end-mass positions `(T, 2)` (pendulum) or
    element positions `(T, N, 3)` (tether)."""

    name: str
    n: int
    lband: int
    uband: int
    rhs: object
    f: object
    jac: object
    end_mass: object
    initial_state: object
    warmup: object


def _peer(name, n, band, kernel, jac_kernel, args, end_mass, initial_state):
    def rhs(t, y, yp):
        kernel(t, y, yp, *args)

    def f(t, y):
        yp = np.empty(n)
        kernel(float(t), np.asarray(y, dtype=np.float64), yp, *args)
        return yp

    jac = None
    if jac_kernel is not None:

        def jac(t, y, JJ):
            jac_kernel(t, y, JJ, *args)

    def warmup():
        """Compile (or load from numba's cache) every kernel; return seconds."""
        import time

        t0 = time.perf_counter()
        y = initial_state()
        f(0.0, y)
        if jac is not None:
            jac(0.0, y, np.zeros((n, n)))
        end_mass(y[None])
        return time.perf_counter() - t0

    return Peer(name, n, band, band, rhs, f, jac, end_mass, initial_state, warmup)


def make_rhs(
    formulation: str,
    k: int,
    EA: float,
    alpha: float = 0.01,
    l: float = 1.0,
    mu: float = 1.0,
    m_s: float = 1.0,
    g: float = G,
    slack: bool = False,
) -> Peer:
    """The string pendulum in `formulation` ("displacement", "natural" = (eps, t),
    "angle" = (eps, phi)), 2D, k elements; EA (N), alpha (s; 0: no damping), l (m),
    mu (kg/m), m_s (kg), g (m/s^2; 0: no gravity), `slack`: the tension-only law.

    `initial_state(theta0=pi/2)`: the straight unstrained string at rest at angle
    theta0 from the downward vertical."""
    if formulation not in FORMULATIONS:
        raise ValueError(
            f"`formulation` must be one of {FORMULATIONS}; got {formulation!r}."
        )
    if int(k) < 2:
        raise ValueError(f"`k` must be an integer >= 2; got {k!r}.")
    k = int(k)
    args = (k, float(EA), float(alpha), float(l), float(mu), float(m_s), float(g))
    args = args + (bool(slack),)
    s = np.arange(k + 1) * (l / k)

    if formulation == "displacement":

        def initial_state(theta0=math.pi / 2):
            r = s[1:, None] * np.array([math.sin(theta0), -math.cos(theta0)])
            return np.concatenate([r, np.zeros_like(r)], axis=1).reshape(-1)

        return _peer(
            "displacement",
            4 * k,
            7,
            _disp_rhs,
            _disp_jac,
            args,
            lambda ys: _disp_end(np.atleast_2d(ys), k),
            initial_state,
        )
    if formulation == "angle":

        def initial_state(theta0=math.pi / 2):
            z = np.zeros(k + 1)
            return np.stack([z, z + theta0, z, z], axis=1).reshape(-1)

        return _peer(
            "angle",
            4 * (k + 1),
            7,
            _angle_rhs,
            None,
            args,
            lambda ys: _natural_end(np.atleast_2d(ys), k, float(l), 4, True),
            initial_state,
        )

    def initial_state(theta0=math.pi / 2):
        z = np.zeros(k + 1)
        sx, sy = math.sin(theta0), -math.cos(theta0)
        return np.stack([z, z + sx, z + sy, z, z, z], axis=1).reshape(-1)

    return _peer(
        "natural",
        6 * (k + 1),
        11,
        _tangent_rhs,
        None,
        args,
        lambda ys: _natural_end(np.atleast_2d(ys), k, float(l), 6, False),
        initial_state,
    )


def make_tether(
    N: int = 101,
    L: float = 100.0,
    d: float = 0.01,
    rho: float = RHO_TABLE1,
    mass_per_length=None,
    added_mass: float = 1.0,
    g: float = G,
    k_s: float = 4e5,
    c_s: float = 0.0,
    c_t: float = 0.1,
    c_n: float = 1.0,
    c_l: float = 0.0,
    current=(-1.0, 0.0, 0.0),
    root=(0.0, 0.0, 0.0),
    times=(0.0, 10.0, 35.0, 45.0, 70.0),
    fast_path=((0, 0, -50), (0, 0, -50), (0, 0, -25), (0, 0, -25), (25, 0, -25)),
) -> Peer:
    """The tether of Blintsov (2017) as lumped masses on N + 1 linear springs of
    stiffness `k_s` (N) and damping `c_s` (N s) between a fixed `root` and a running
    end on the piecewise-linear `fast_path` (m, one point per knot of `times`, s).

    Each of the N elements stands for l_e = L/N of cable of diameter `d` (mass
    `mass_per_length` l_e, kg/m; None: neutrally buoyant, rho pi d^2/4) plus the
    added mass `added_mass` rho Q_e (Q_e = pi d^2/4 l_e); springs of rest length
    L/(N + 1). Loads: weight and buoyancy (g, rho), and quadratic drag in the
    uniform `current` (m/s) with coefficients `c_t` (tangential, on the projected
    area d l_e), `c_n` (normal), `c_l` (lateral, c_l v_t (i x v_f)). State row n =
    (p_n, v_n) (m, m/s); `end_mass(ys)` returns the element positions `(T, N, 3)`;
    `initial_state()` a straight line between the mounts (a warm-up state: take the
    scene's initial shape for runs)."""
    if int(N) < 2:
        raise ValueError(f"`N` must be an integer >= 2; got {N!r}.")
    N = int(N)
    le = L / N
    Q = 0.25 * math.pi * d**2 * le
    mpl = rho * 0.25 * math.pi * d**2 if mass_per_length is None else mass_per_length
    m_e = mpl * le
    args = (
        N,
        L / (N + 1),
        m_e + added_mass * rho * Q,
        float(k_s),
        float(c_s),
        (rho * Q - m_e) * g,  # buoyancy minus weight, along +z
        0.5 * rho * d * le,
        float(c_t) / math.pi,  # on the wetted area pi d l_e: the same force
        float(c_n),
        float(c_l),
        np.asarray(current, dtype=np.float64),
        np.asarray(root, dtype=np.float64),
        np.asarray(times, dtype=np.float64),
        np.asarray(fast_path, dtype=np.float64).reshape(-1, 3),
    )

    def initial_state():
        a = np.asarray(root, dtype=np.float64)
        b = np.asarray(fast_path, dtype=np.float64)[0]
        s = np.arange(1, N + 1)[:, None] / (N + 1)
        return np.concatenate([a + s * (b - a), np.zeros((N, 3))], axis=1).ravel()

    return _peer(
        "tether",
        6 * N,
        11,
        _tether_rhs,
        None,
        args,
        lambda ys: np.atleast_2d(ys).reshape(-1, N, 6)[:, :, :3].copy(),
        initial_state,
    )


# ---------------------------------------------------------------------------
# Solvers


def _analytic(peer, jac) -> bool:
    """Whether `jac` asks for the peer's exact Jacobian (refusing what it lacks)."""
    if jac not in ("analytic", "dq"):
        raise ValueError(f"`jac` must be 'analytic' or 'dq'; got {jac!r}.")
    if jac == "analytic" and peer.jac is None:
        raise ValueError(f"`jac`: the {peer.name} peer has no analytic Jacobian.")
    return jac == "analytic"


def cvode_solve(
    peer: Peer, ts, y0, rtol, atol, jac="analytic", max_num_steps=1_000_000
) -> dict:
    """CVODE BDF with the band linear solver from `y0` at `ts[0]`, output at `ts`.

    `jac`: "analytic" (the peer's exact Jacobian; only where it has one) or "dq"
    (CVODE's banded difference quotients). Returns a dict: `ys` `(T, n)` (None on
    failure), `ok`, `message`, `nfev` and `njev` (right-hand side and Jacobian
    evaluations, CVODE's counts)."""
    from sksundae.cvode import CVODE

    kw = {}
    if _analytic(peer, jac):
        pj = peer.jac
        kw["jacfn"] = lambda t, y, yp, JJ: pj(t, y, JJ)
    solver = CVODE(
        peer.rhs,
        method="BDF",
        rtol=rtol,
        atol=atol,
        linsolver="band",
        lband=peer.lband,
        uband=peer.uband,
        max_num_steps=max_num_steps,
        **kw,
    )
    ts = np.asarray(ts, dtype=np.float64)
    sol = solver.solve(ts, np.asarray(y0, dtype=np.float64))
    ok = bool(sol.success) and sol.y.shape[0] == len(ts)
    return {
        "ys": np.asarray(sol.y) if ok else None,
        "ok": ok,
        "message": str(sol.message),
        "nfev": int(sol.nfev),
        "njev": int(sol.njev),
    }


def _band_pattern(peer):
    i, j = np.indices((peer.n, peer.n))
    return ((i - j) <= peer.lband) & ((j - i) <= peer.uband)


class _Deadline(RuntimeError):
    pass


def scipy_solve(
    peer: Peer, method, ts, y0, rtol, atol, jac="analytic", cpu_limit_s=None
) -> dict:
    """scipy's solve_ivp (`method` "BDF", "Radau" or "LSODA") on the peer's compiled
    right-hand side, with its exact Jacobian (`jac="analytic"`: sparse for BDF and
    Radau, LSODA's packed band) or scipy's finite differences on the band pattern
    (`jac="dq"`). A run past `cpu_limit_s` seconds of process CPU stops and fails.
    Returns a dict like `cvode_solve`'s."""
    import time

    from scipy.integrate import solve_ivp
    from scipy.sparse import csc_matrix

    kw = {}
    if _analytic(peer, jac):
        JJ = np.zeros((peer.n, peer.n))
        bi, bj = np.nonzero(_band_pattern(peer))

        def band_values(t, y):
            peer.jac(t, y, JJ)
            return JJ[bi, bj]

        if method == "LSODA":

            def packed(t, y):
                out = np.zeros((peer.lband + peer.uband + 1, peer.n))
                out[peer.uband + bi - bj, bj] = band_values(t, y)
                return out

            kw.update(jac=packed, lband=peer.lband, uband=peer.uband)
        else:
            kw["jac"] = lambda t, y: csc_matrix(
                (band_values(t, y), (bi, bj)), shape=(peer.n, peer.n)
            )
    elif method == "LSODA":
        kw.update(lband=peer.lband, uband=peer.uband)
    else:
        kw["jac_sparsity"] = _band_pattern(peer)
    ts = np.asarray(ts, dtype=np.float64)
    f = peer.f
    if cpu_limit_s is not None:
        stop = time.process_time() + cpu_limit_s

        def f(t, y):
            if time.process_time() > stop:
                raise _Deadline(f"more than {cpu_limit_s:g} s of CPU")
            return peer.f(t, y)

    try:
        sol = solve_ivp(
            f,
            (ts[0], ts[-1]),
            np.asarray(y0, dtype=np.float64),
            method=method,
            t_eval=ts,
            rtol=rtol,
            atol=atol,
            **kw,
        )
    except _Deadline as e:
        return {"ys": None, "ok": False, "message": str(e), "nfev": -1, "njev": -1}
    ok = bool(sol.success) and sol.y.shape[1] == len(ts)
    return {
        "ys": sol.y.T if ok else None,
        "ok": ok,
        "message": str(sol.message),
        "nfev": int(sol.nfev),
        "njev": int(sol.njev),
    }
