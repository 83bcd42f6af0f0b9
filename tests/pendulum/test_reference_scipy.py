"""Independent reference check of the displacement-variable string pendulum.

The right-hand side below is a separate pure-NumPy implementation of Poth et al.
eqs 11-14 (see ``shared/specs/string_pendulum.md``, formulation 1), integrated with
SciPy's Radau at tight tolerances. It imports nothing from jaxstring. jaxstring's
``DisplacementString`` + Kvaerno5 must reproduce its end-mass trajectory, element
tensions and total energy.

Reference model (k elements, h = l/k, node 0 = pivot fixed at the origin):
    D+ r_i = (r_{i+1} - r_i)/h,  D- r_i = (r_i - r_{i-1})/h,
    eps = |D r| - 1,  epsdot = (D rdot . D r)/(eps + 1),  t = D r/(eps + 1),
    N = EA (eps + alpha epsdot),
    interior:  rddot_i = (k/(mu l)) (N+ t+ - N- t-) + g,
    end node:  m_s rddot_k = -N-_k t-_k + m_s g   (end node carries m_s only).
State layout: flat [r_1, ..., r_k, v_1, ..., v_k] (x, y interleaved per node).

OPENBLAS_NUM_THREADS=1 is requested below, but it only takes effect if NumPy has not
been imported yet (e.g. by a conftest or another test module); jaxstring also limits
OpenBLAS threads on import. The whole module runs in about 15 s on 2 cores.
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import functools

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ..helpers import run


K = 10
EA = 1e4
L = 1.0
MU = 1.0
M_S = 1.0
GRAV = 9.81
T1 = 1.0
N_SAVE = 21
M_TOTAL = MU * L + M_S  # kg, string + end mass
ENERGY_SCALE = M_TOTAL * GRAV * L  # J

END_MASS_TOL = 1e-6  # m: the agreement required of the two codes
TENSION_RTOL = 1e-5  # of the largest tension over the run
ENERGY_CONSERVATION_RTOL = 1e-8  # of M_TOTAL g l, reference with alpha = 0
ENERGY_MATCH_RTOL = 1e-6  # of M_TOTAL g l, jaxstring vs reference


class _ReferenceString:
    """Pure-NumPy displacement-variable string pendulum (eqs 11-14)."""

    def __init__(self, k, EA, alpha, l=1.0, mu=1.0, m_s=1.0, g=9.81):
        self.k, self.EA, self.alpha = k, EA, alpha
        self.l, self.mu, self.m_s = l, mu, m_s
        self.gvec = np.array([0.0, -g])
        # Mass of nodes 1..k: mu l/k at interior nodes, m_s (only) at the end node.
        self.masses = np.full(k, mu * l / k)
        self.masses[-1] = m_s

    def y0(self):
        """Straight, horizontal to the right, unstrained, at rest."""
        r = np.zeros((self.k, 2))
        r[:, 0] = np.arange(1, self.k + 1) * self.l / self.k
        return np.concatenate([r.ravel(), np.zeros(2 * self.k)])

    def nodes(self, y):
        """Positions and velocities of nodes 0..k (pivot included), (k+1, 2) each."""
        r = np.zeros((self.k + 1, 2))
        v = np.zeros((self.k + 1, 2))
        r[1:] = y[: 2 * self.k].reshape(self.k, 2)
        v[1:] = y[2 * self.k :].reshape(self.k, 2)
        return r, v

    def elements(self, y):
        """Per element e (nodes e, e+1): D r, D rdot, |D r|, t, eps, epsdot, N."""
        r, v = self.nodes(y)
        c = self.k / self.l
        d = c * (r[1:] - r[:-1])
        dv = c * (v[1:] - v[:-1])
        s = np.sqrt(np.sum(d * d, axis=1))
        t = d / s[:, None]
        eps = s - 1.0
        eps_dot = np.sum(dv * d, axis=1) / s
        N = self.EA * (eps + self.alpha * eps_dot)
        return d, dv, s, t, eps, eps_dot, N

    def rhs(self, _t, y):
        k = self.k
        *_, t, _, _, N = self.elements(y)
        F = N[:, None] * t  # N t of each element
        force = -F  # node i (row i-1): -N-_i t-_i from element i-1
        force[:-1] += F[1:]  # +N+_i t+_i from element i (not at the end node)
        acc = force / self.masses[:, None] + self.gvec
        return np.concatenate([y[2 * k :], acc.ravel()])

    def jac(self, _t, y):
        """Analytic Jacobian of `rhs`, dense (4k, 4k)."""
        k, EA, alpha = self.k, self.EA, self.alpha
        d, dv, s, t, _, _, N = self.elements(y)
        c = k / self.l
        eye = np.eye(2)
        J = np.zeros((4 * k, 4 * k))
        J[: 2 * k, 2 * k :] = np.eye(2 * k)
        for e in range(k):
            tt = np.outer(t[e], t[e])
            dN_dd = EA * (t[e] + alpha * (dv[e] - (dv[e] @ t[e]) * t[e]) / s[e])
            dF_dd = np.outer(t[e], dN_dd) + N[e] * (eye - tt) / s[e]
            dF_ddv = EA * alpha * tt
            # Element e acts on node e+1 (row e) with -F and on node e (row e-1)
            # with +F; D r of element e is c (r_{e+1} - r_e).
            for row, f_sign in ((e, -1.0), (e - 1, 1.0)):
                if row < 0:
                    continue
                ra = 2 * k + 2 * row
                for col, d_sign in ((e, c), (e - 1, -c)):
                    if col < 0:
                        continue
                    w = f_sign * d_sign / self.masses[row]
                    J[ra : ra + 2, 2 * col : 2 * col + 2] += w * dF_dd
                    cv = 2 * k + 2 * col
                    J[ra : ra + 2, cv : cv + 2] += w * dF_ddv
        return J

    def energy(self, y):
        """Kinetic + elastic + gravity potential, J (same mass lumping)."""
        r, v = self.nodes(y)
        _, _, _, _, eps, _, _ = self.elements(y)
        kinetic = 0.5 * np.sum(self.masses * np.sum(v[1:] ** 2, axis=1))
        elastic = 0.5 * self.EA * (self.l / self.k) * np.sum(eps**2)
        gravity = -np.sum(self.masses * (r[1:] @ self.gvec))
        return kinetic + elastic + gravity

    def solve(self, ts, rtol=1e-10, atol_pos=1e-12, atol_vel=1e-10):
        n = 2 * self.k
        atol = np.concatenate([np.full(n, atol_pos), np.full(n, atol_vel)])
        return solve_ivp(
            self.rhs,
            (ts[0], ts[-1]),
            self.y0(),
            method="Radau",
            t_eval=ts,
            rtol=rtol,
            atol=atol,
            jac=self.jac,
        )


def _ts():
    return np.linspace(0.0, T1, N_SAVE)


@functools.cache
def _reference(alpha):
    """Reference run: (model, states (N_SAVE, 4k))."""
    model = _ReferenceString(K, EA, alpha, l=L, mu=MU, m_s=M_S, g=GRAV)
    sol = model.solve(_ts())
    assert sol.success, f"Radau reference failed (alpha={alpha}): {sol.message}"
    return model, sol.y.T


def _jaxstring(alpha):
    traj = run(
        "displacement",
        k=K,
        EA=EA,
        alpha=alpha,
        t1=T1,
        rtol=1e-10,
        atol=1e-10,
        n_save=N_SAVE,
        mu=MU,
        m_s=M_S,
        l=L,
        g=GRAV,
    )
    assert traj.ok, f"jaxstring failed (alpha={alpha}): {traj.status}"
    return traj


ALPHAS = pytest.mark.parametrize("alpha", [0.01, 0.0])


def test_reference_jacobian_matches_finite_differences():
    model = _ReferenceString(K, EA, 0.01, l=L, mu=MU, m_s=M_S, g=GRAV)
    rng = np.random.default_rng(0)
    y = model.y0() + 1e-2 * rng.standard_normal(4 * K)
    J = model.jac(0.0, y)
    h = 1e-6
    J_fd = np.empty_like(J)
    for j in range(4 * K):
        dy = np.zeros(4 * K)
        dy[j] = h
        J_fd[:, j] = (model.rhs(0.0, y + dy) - model.rhs(0.0, y - dy)) / (2 * h)
    err = np.max(np.abs(J - J_fd)) / np.max(np.abs(J))
    assert err < 1e-7, f"analytic Jacobian vs central differences: rel err {err:.3e}"


def test_reference_initial_acceleration_is_gravity():
    # Straight, unstrained and at rest: no tension, every node falls freely (up to
    # round-off in eps, ~1e-16, times EA k/(mu l) = 1e5).
    model = _ReferenceString(K, EA, 0.01, l=L, mu=MU, m_s=M_S, g=GRAV)
    acc = model.rhs(0.0, model.y0())[2 * K :].reshape(K, 2)
    np.testing.assert_allclose(acc, np.tile([0.0, -GRAV], (K, 1)), atol=1e-8)


@ALPHAS
def test_end_mass_matches_reference(alpha):
    _, ys = _reference(alpha)
    traj = _jaxstring(alpha)
    ref_end = ys[:, 2 * K - 2 : 2 * K]
    err_t = np.max(np.abs(np.asarray(traj.end_mass) - ref_end), axis=1)
    worst = int(np.argmax(err_t))
    assert err_t[worst] <= END_MASS_TOL, (
        f"alpha={alpha}: end mass differs from the SciPy Radau reference by "
        f"{err_t[worst]:.3e} m at t={_ts()[worst]:.2f} s (tol {END_MASS_TOL:g} m); "
        f"per save time: {np.array2string(err_t, precision=2)}"
    )
    # All nodes, pivot included (stronger than the requirement).
    ref_pos = np.concatenate(
        [np.zeros((N_SAVE, 1, 2)), ys[:, : 2 * K].reshape(N_SAVE, K, 2)], axis=1
    )
    err_nodes = np.max(np.abs(np.asarray(traj.positions) - ref_pos))
    assert err_nodes <= END_MASS_TOL, (
        f"alpha={alpha}: node positions differ from the reference by "
        f"{err_nodes:.3e} m (tol {END_MASS_TOL:g} m)"
    )


@ALPHAS
def test_tension_matches_reference(alpha):
    model, ys = _reference(alpha)
    traj = _jaxstring(alpha)
    N_ref = np.stack([model.elements(y)[-1] for y in ys])
    N_jax = np.asarray(traj.tension)
    assert N_jax.shape == (N_SAVE, K), f"tension shape {N_jax.shape}"
    scale = np.max(np.abs(N_ref))
    err = np.abs(N_jax - N_ref)
    t_i, e_i = np.unravel_index(np.argmax(err), err.shape)
    assert err[t_i, e_i] <= TENSION_RTOL * scale, (
        f"alpha={alpha}: element tension differs from the reference by "
        f"{err[t_i, e_i]:.3e} N (element {e_i}, t={_ts()[t_i]:.2f} s); "
        f"tol {TENSION_RTOL:g} x max|N| = {TENSION_RTOL * scale:.3e} N"
    )


def _reference_energy(alpha):
    model, ys = _reference(alpha)
    return np.array([model.energy(y) for y in ys])


def test_reference_energy_conserved_without_damping():
    E = _reference_energy(0.0)
    drift = np.max(np.abs(E - E[0]))
    assert drift <= ENERGY_CONSERVATION_RTOL * ENERGY_SCALE, (
        f"reference energy drift {drift:.3e} J with alpha=0 "
        f"(tol {ENERGY_CONSERVATION_RTOL:g} x m g l = "
        f"{ENERGY_CONSERVATION_RTOL * ENERGY_SCALE:.3e} J)"
    )


def test_reference_energy_decays_with_damping():
    E = _reference_energy(0.01)
    rise = np.max(np.diff(E))
    assert rise <= ENERGY_CONSERVATION_RTOL * ENERGY_SCALE, (
        f"reference energy rises by {rise:.3e} J between save times with alpha=0.01"
    )
    assert E[-1] < E[0], f"no dissipation: E(0)={E[0]:.6e} J, E(t1)={E[-1]:.6e} J"


@ALPHAS
def test_energy_matches_reference(alpha):
    traj = _jaxstring(alpha)
    E_ref = _reference_energy(alpha)
    err_t = np.abs(np.asarray(traj.energy) - E_ref)
    worst = int(np.argmax(err_t))
    assert err_t[worst] <= ENERGY_MATCH_RTOL * ENERGY_SCALE, (
        f"alpha={alpha}: jaxstring energy differs from the NumPy energy by "
        f"{err_t[worst]:.3e} J at t={_ts()[worst]:.2f} s "
        f"(tol {ENERGY_MATCH_RTOL:g} x m g l = "
        f"{ENERGY_MATCH_RTOL * ENERGY_SCALE:.3e} J)"
    )
