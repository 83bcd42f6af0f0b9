"""String pendulum models: displacement variables and natural variables.

Three final classes share one interface (see ``AbstractString``):

* ``DisplacementString``: node positions and velocities, eqs 11-14 of Poth et al.
  The end node carries the end mass m_s only (the paper's lumping).
* ``NaturalTangentString``: strain eps and Cartesian unit tangent t at the nodes
  s_i = i l / k, i = 0..k (eqs 15-23), 2D or 3D; the unit-length constraint is
  kept by projecting the state after each step, so it cannot drift.
* ``NaturalAngleString``: strain eps and tangent angle phi (2D),
  t = (sin phi, -cos phi).

State layout is node-major (one row per node) so that the Jacobian of every model is
block-banded, which the linear algebra of the implicit solvers can exploit.
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .._arrays import FloatScalar, f64
from .._geometry import direction, safe_norm
from .._linalg.banded import BlockTridiagonal, SecondOrderJacobian
from .._model import AbstractModel, SolverStructure
from .._validate import check_int, check_positive, check_shape
from ..chain import Gravity
from .effects import (
    AbstractStringLoad,
    AbstractTensionLaw,
    KelvinVoigt,
    Kinematics,
    Slack,
    apply_laws,
    elastic_strain,
    split_effects,
    total_loads,
)


def _param():
    return eqx.field(converter=f64)


class AbstractString(AbstractModel):
    """A string of unstrained length `l` with an end mass, hanging from a fixed pivot.

    **Fields:** `l` (m), `mu` (kg/m), `m_s` (kg), `EA` (N) are differentiable
    parameters; `k` (number of elements) and `dim` (2 or 3) are structure.
    """

    l: FloatScalar = _param()
    mu: FloatScalar = _param()
    m_s: FloatScalar = _param()
    EA: FloatScalar = _param()
    k: int = eqx.field(static=True)
    dim: int = eqx.field(static=True, default=2)
    formulation: ClassVar[str]
    accepts: ClassVar[tuple[type, ...]] = (
        Gravity,
        AbstractStringLoad,
        AbstractTensionLaw,
    )

    def __check_init__(self):
        _check_string(self)

    def elastic_energy(self, y, effects):
        """Elastic energy stored in the string, J."""
        _, laws = split_effects(effects)
        eps, _ = self.strain(y)
        e = elastic_strain(laws, eps)
        return 0.5 * self.EA * jnp.sum(self.tension_weights() * e**2)

    def constraint_error(self, y):
        """Largest violation of the model's kinematic constraint (0 if it has none)."""
        return jnp.zeros((), y.dtype)

    def project(self, y):
        return y

    def state_shape(self):
        # the shape alone: nothing is computed (or compiled); the formulations
        # give it without tracing `initial_state`
        return jax.eval_shape(self.initial_state, 0.0).shape

    @property
    def preset_system(self) -> str:
        return self.formulation

    @staticmethod
    def _local(effects) -> bool:
        """Whether every effect is one of jaxstring's own string effects, which act
        element by element (each node then couples only to its neighbours)."""
        return all(type(e) in (Gravity, KelvinVoigt, Slack) for e in effects)

    def structure(self, effects):
        """Band 1 under jaxstring's own string effects (None: detect, under any
        other); the displacement string also has the (r, r') layout, its own
        Jacobian, and stiff directions that turn with the string (a Jacobian per
        implicit stage and per BDF step). tests/solvers/test_fast_solvers.py checks the
        band against detection, tests/solvers/test_linalg.py the Jacobian against
        the JVP-built one."""
        local = self._local(effects)
        if self.formulation != "displacement":
            return SolverStructure(bandwidth=1 if local else None)
        return SolverStructure(
            bandwidth=1 if local else None,
            second_order=self.dim,
            stage_jacobians=True,
            step_jacobians=True,
            jacobian=local,
        )

    def observables(self, t, y, effects, env):
        """Node positions and velocities (pivot included), tension and strain at the
        tension points, total energy and constraint error."""
        del t
        kin = self.kinematics(y)
        eps, _ = self.strain(y)
        return {
            "positions": kin.positions,
            "velocities": kin.velocities,
            "tension": tension(self, y, effects),
            "strain": eps,
            "energy": energy(self, y, effects, env),
            "constraint_error": self.constraint_error(y),
        }

    @abc.abstractmethod
    def initial_state(self, theta0) -> Array:
        """Straight, unstrained string at rest, at angle `theta0` (rad) from the
        downward vertical towards +x."""

    @abc.abstractmethod
    def kinematics(self, y) -> Kinematics:
        """Positions and velocities of the nodes, pivot included: `(k + 1, dim)`."""

    @abc.abstractmethod
    def strain(self, y) -> tuple[Array, Array]:
        """Return (strain, strain rate) at the points where tension is defined."""

    @abc.abstractmethod
    def node_masses(self) -> Array:
        """Mass lumped at each node (pivot included, end mass included), kg."""

    @abc.abstractmethod
    def vector_field(self, t, y, effects, env) -> Array:
        """dy/dt of the state `y` at time `t` (s) under `effects` in `env`."""

    @abc.abstractmethod
    def kinetic_energy(self, y) -> Array:
        """Kinetic energy of string and end mass, J."""

    @abc.abstractmethod
    def constant_load_potential(self, y, loads) -> Array:
        """Potential energy of position-independent loads (minus their work), J."""

    @abc.abstractmethod
    def tension_weights(self) -> Array:
        """Unstrained length each tension point stands for (quadrature weights), m."""


def _check_string(model) -> None:
    for name, unit in (("l", "m"), ("mu", "kg/m"), ("m_s", "kg"), ("EA", "N")):
        check_shape(name, getattr(model, name), (), unit)
        check_positive(name, getattr(model, name), unit)
    check_int("k", model.k, 2)
    if model.dim not in (2, 3):
        raise ValueError(f"`dim` must be 2 or 3; got {model.dim!r}.")


def tension(model: AbstractString, y, effects) -> Array:
    """Axial force at the model's tension points (elements or nodes), N."""
    _, laws = split_effects(effects)
    eps, eps_dot = model.strain(y)
    return apply_laws(laws, model.EA, eps, eps_dot)


def energy(model: AbstractString, y, effects, env) -> Array:
    """Total mechanical energy (kinetic + elastic + potentials of the loads), J.

    A constant load's potential is minus its work in the model's own coordinates
    (`constant_load_potential`); other loads store none."""
    loads, _ = split_effects(effects)
    constant = [e for e in loads if e.constant]
    potential = jnp.zeros(())
    if constant:
        kin = model.kinematics(y)
        for e in constant:
            f = e.forces(0.0, kin, env)
            potential = potential + model.constant_load_potential(y, f)
    return model.kinetic_energy(y) + model.elastic_energy(y, effects) + potential


def _trapezoid_weights(l, k):
    w = jnp.full((k + 1,), l / k)
    return w.at[0].set(0.5 * l / k).at[-1].set(0.5 * l / k)


def _cumtrapz_nodes(f, h):
    """Cumulative trapezoid integral of nodal values f (k+1, d) from node 0."""
    seg = 0.5 * h * (f[1:] + f[:-1])
    return jnp.concatenate([jnp.zeros_like(f[:1]), jnp.cumsum(seg, axis=0)], axis=0)


class DisplacementString(AbstractString):
    """String in displacement variables (Poth et al. eqs 11-14).

    State `y`: shape `(k, 2 dim)`, row i-1 = (r_i, r_i') for nodes i = 1..k (m, m/s).
    Tension is defined on the k elements.
    """

    formulation: ClassVar[str] = "displacement"
    projects: ClassVar[bool] = False

    def state_shape(self):
        return (self.k, 2 * self.dim)

    def initial_state(self, theta0):
        s = jnp.arange(1, self.k + 1) * (self.l / self.k)
        r = s[:, None] * direction(theta0, self.dim)[None, :]
        return jnp.concatenate([r, jnp.zeros_like(r)], axis=1)

    def kinematics(self, y):
        zero = jnp.zeros((1, self.dim), y.dtype)
        r = jnp.concatenate([zero, y[:, : self.dim]], axis=0)
        v = jnp.concatenate([zero, y[:, self.dim :]], axis=0)
        return Kinematics(r, v, self.mu, self.m_s)

    def _rows(self, kin):
        """D+ r and D+ r', one row per element."""
        h = self.l / self.k
        return (
            jnp.diff(kin.positions, axis=0) / h,
            jnp.diff(kin.velocities, axis=0) / h,
        )

    def _elements(self, kin):
        return _element_strains(*self._rows(kin))

    def strain(self, y):
        eps, eps_dot, _ = self._elements(self.kinematics(y))
        return eps, eps_dot

    def node_masses(self):
        m = jnp.full((self.k + 1,), self.mu * self.l / self.k)
        return m.at[0].set(0.0).at[-1].set(self.m_s)

    def tension_weights(self):
        return jnp.full((self.k,), self.l / self.k)

    def vf_jacobian(self, t, y, effects, env):
        """The exact Jacobian of `vector_field`, element by element
        (`AbstractModel.vf_jacobian`), under jaxstring's string effects (gravity is
        constant; the tension laws act on each element's own strain and strain
        rate); None under any other effect.

        Element e's force F_e = N t depends only on its rows d = D+ r and
        dv = D+ r', so dF_e/dd and dF_e/d(dv) are written out (d x d blocks, two
        element-wise JVPs of the tension laws for dN/d eps and dN/d eps_dot). This
        costs about half of the 3 x 2 d coloured JVPs of the whole vector field
        that the generic probe needs, and the result is the `SecondOrderJacobian`
        the reduced factorisation uses, without forming the q rows. With c_j the
        inverse mass of node j and M_e = dF_e/d(d, dv) / h, the acceleration rows
        of node j are -c_j (M_j + M_(j+1)) on the diagonal, c_j M_(j+1) above and
        c_j M_j below (no element beyond the end node; element 0 hangs from the
        fixed pivot)."""
        del t, env
        if not self._local(effects):
            return None
        _, laws = split_effects(effects)
        k, dim = self.k, self.dim
        h = self.l / k
        d, dv = self._rows(self.kinematics(y))
        eps, eps_dot, t_ = _element_strains(d, dv)
        # N and its partial derivatives from two element-wise JVPs of the laws.
        law = lambda e, ed: apply_laws(laws, self.EA, e, ed)
        N, N_eps = jax.jvp(
            law, (eps, eps_dot), (jnp.ones_like(eps), jnp.zeros_like(eps))
        )
        N_rate = jax.jvp(
            law, (eps, eps_dot), (jnp.zeros_like(eps), jnp.ones_like(eps))
        )[1]
        stretch = eps + 1.0
        safe = jnp.where(stretch > 0, stretch, 1.0)[:, None, None]
        tt = t_[:, :, None] * t_[:, None, :]
        eye = jnp.eye(dim, dtype=y.dtype)
        # F = N(eps, eps_dot) t with eps = |d| - 1, t = d / |d|, eps_dot = dv . t:
        # dt/dd = (I - t t^T) / |d|, d eps_dot / dd = (dv - eps_dot t) / |d|.
        dF_dd = (
            N_eps[:, None, None] * tt
            + (N[:, None, None] / safe) * (eye - tt)
            + (N_rate[:, None, None] / safe)
            * t_[:, :, None]
            * (dv - eps_dot[:, None] * t_)[:, None, :]
        )
        dF_ddv = N_rate[:, None, None] * tt
        M = jnp.concatenate([dF_dd, dF_ddv], axis=-1) / h  # (k, dim, 2 dim)
        c = jnp.full((k,), k / (self.mu * self.l)).at[-1].set(1.0 / self.m_s)
        c = c[:, None, None]
        M_next = jnp.concatenate([M[1:], jnp.zeros_like(M[:1])])  # none past the end
        M_prev = M.at[0].set(0.0)  # element 0 hangs from the fixed pivot
        lower, diag, upper = c * M_prev, -c * (M + M_next), c * M_next
        part = lambda lo, hi: BlockTridiagonal(
            lower[..., lo:hi], diag[..., lo:hi], upper[..., lo:hi], k, dim, 1
        )
        return SecondOrderJacobian(
            part(0, dim),
            part(dim, 2 * dim),
            jnp.zeros((), y.dtype),
            jnp.ones((), y.dtype),
        )

    def vector_field(self, t, y, effects, env):
        loads, laws = split_effects(effects)
        kin = self.kinematics(y)
        eps, eps_dot, tangent = self._elements(kin)
        N = apply_laws(laws, self.EA, eps, eps_dot)
        Nt = N[:, None] * tangent  # force of element e on node e+1 is -Nt[e]
        # Interior nodes 1..k-1: (k/(mu l)) (N+ t+ - N- t-) (eq 14).
        acc_int = (Nt[1:] - Nt[:-1]) * (self.k / (self.mu * self.l))
        acc_end = -Nt[-1] / self.m_s  # eq 4
        if loads:
            f = total_loads(loads, t, kin, env)
            acc_int = acc_int + f.line[1:-1] / self.mu
            acc_end = acc_end + f.end / self.m_s
        acc = jnp.concatenate([acc_int, acc_end[None, :]], axis=0)
        return jnp.concatenate([y[:, self.dim :], acc], axis=1)

    def kinetic_energy(self, y):
        v = self.kinematics(y).velocities
        return 0.5 * jnp.sum(self.node_masses() * jnp.sum(v**2, -1))

    def constant_load_potential(self, y, loads):
        # Work coordinates of the lumped model: the interior nodes carry the line
        # load of one element, the end node the end force (eq 14 and eq 4).
        r = self.kinematics(y).positions
        h = self.l / self.k
        return -(h * jnp.sum(loads.line[1:-1] * r[1:-1]) + jnp.sum(loads.end * r[-1]))


def _element_strains(d, dv):
    """Strain, strain rate and unit tangent of elements with D+ r = d, D+ r' = dv."""
    stretch = safe_norm(d)
    safe = jnp.where(stretch > 0, stretch, 1.0)
    t = d / safe[:, None]
    eps_dot = jnp.sum(dv * d, -1) / safe
    return stretch - 1.0, eps_dot, t


def _apply_minv_neg(z, k, l, a):
    """x = -M^{-1} z with the tridiagonal M^{-1} of eq 17.

    The last diagonal entry is 2 (1 + 1/a) k^2/l^2 with a = k m_s/(mu l): the paper
    prints 2(a + 1), which contradicts its own eq 19 (and its units); this value is
    the exact inverse of its M and reproduces eq 19.
    """
    c = (k / l) ** 2
    x0 = -c * (2 * z[0] - 2 * z[1])
    xi = -c * (-z[:-2] + 2 * z[1:-1] - z[2:])
    xk = -c * (-2 * z[-2] + 2 * (1 + 1 / a) * z[-1])
    return jnp.concatenate([x0[None], xi, xk[None]], axis=0)


def _tail_forces(model, loads):
    """External force on the piece [s_i, l] plus the end mass, per node, N."""
    h = model.l / model.k
    seg = 0.5 * h * (loads.line[1:] + loads.line[:-1])
    tail = jnp.concatenate(
        [jnp.cumsum(seg[::-1], axis=0)[::-1], jnp.zeros_like(seg[:1])], axis=0
    )
    return tail + loads.end[None, :]


def _natural_kinetic_energy(model, q_dot):
    """Kinetic energy that the natural-variable discretisation conserves.

    Multiplying M x + z = 0 by the trapezoid weights C gives the symmetric mass
    matrix mu C G C (G the Green's matrix of eq 10), so the conserved kinetic energy
    is mu/2 sum_ij w_i w_j G_ij q_i' . q_j' with q = (1 + eps) t. Written with the
    partial sums Q_m = sum_{i <= m} w_i q_i': mu h/2 sum_{m<k} |Q_m|^2 + m_s/2 |Q_k|^2
    (O(k); Q_k is the end-mass velocity).
    """
    w = _trapezoid_weights(model.l, model.k)
    Q = jnp.cumsum(w[:, None] * q_dot, axis=0)
    h = model.l / model.k
    return 0.5 * model.mu * h * jnp.sum(Q[:-1] ** 2) + 0.5 * model.m_s * jnp.sum(
        Q[-1] ** 2
    )


def _natural_load_potential(model, q, loads):
    """Potential of constant loads consistent with eq 10: -sum_i w_i F_i . q_i."""
    w = _trapezoid_weights(model.l, model.k)
    return -jnp.sum(w[:, None] * _tail_forces(model, loads) * q)


def _natural_x(model, t, kin, tangent, N, loads, env):
    """Second time derivative x_i = [(1 + eps_i) t_i]'' from eqs 15-19.

    External loads generalise the gravity term of z: z_i = (N_i t_i - F_i)/mu with
    F_i the external force on the piece [s_i, l] plus the end mass (trapezoid rule
    on each element), which for gravity is exactly (m_s + mu (l - s_i)) g.
    """
    z = N[:, None] * tangent
    if loads:
        z = z - _tail_forces(model, total_loads(loads, t, kin, env))
    z = z / model.mu
    a = model.k * model.m_s / (model.mu * model.l)
    return _apply_minv_neg(z, model.k, model.l, a)


class _AbstractNaturalString(AbstractString):
    """Natural variables: strain and direction at the nodes, integrated along the
    string by the trapezoidal rule (node masses and tension weights alike)."""

    def node_masses(self):
        m = self.mu * _trapezoid_weights(self.l, self.k)
        return m.at[-1].add(self.m_s)

    def tension_weights(self):
        return _trapezoid_weights(self.l, self.k)


class NaturalTangentString(_AbstractNaturalString):
    """String in natural variables: strain eps and Cartesian tangent t (eqs 15-23).

    State `y`: shape `(k + 1, 2 + 2 dim)`, row i = (eps_i, t_i, eps_i', t_i') at node
    s_i = i l/k. Positions follow from r(s) = int_0^s (1 + eps) t ds (trapezoid rule).
    The constraint |t| = 1 is enforced through its second derivative (eqs 21-23) with
    Baumgarte stabilisation c'' + 2 w c' + w^2 c = 0, c = (|t|^2 - 1)/2, at the rate
    w = sqrt(EA/mu) k/l of the axial waves: no new time scale, and drift decays.
    """

    formulation: ClassVar[str] = "natural"
    projects: ClassVar[bool] = True

    def _split(self, y):
        d = self.dim
        return y[:, 0], y[:, 1 : 1 + d], y[:, 1 + d], y[:, 2 + d :]

    def state_shape(self):
        return (self.k + 1, 2 + 2 * self.dim)

    def initial_state(self, theta0):
        n = self.k + 1
        t = jnp.broadcast_to(direction(theta0, self.dim), (n, self.dim))
        z1 = jnp.zeros((n, 1))
        return jnp.concatenate([z1, t, z1, jnp.zeros((n, self.dim))], axis=1)

    def kinematics(self, y):
        eps, t, eps_dot, t_dot = self._split(y)
        h = self.l / self.k
        r_s = (1 + eps)[:, None] * t
        v_s = eps_dot[:, None] * t + (1 + eps)[:, None] * t_dot
        return Kinematics(
            _cumtrapz_nodes(r_s, h), _cumtrapz_nodes(v_s, h), self.mu, self.m_s
        )

    def strain(self, y):
        eps, _, eps_dot, _ = self._split(y)
        return eps, eps_dot

    def vector_field(self, t, y, effects, env):
        loads, laws = split_effects(effects)
        eps, tan, eps_dot, tan_dot = self._split(y)
        kin = self.kinematics(y) if loads else None
        N = apply_laws(laws, self.EA, eps, eps_dot)
        x = _natural_x(self, t, kin, tan, N, loads, env)
        # Solve eq 22 for (t'', eps''), for any |t| (eq 23 assumes |t| = 1):
        # (1+eps) t'' + eps'' t = x - 2 eps' t' =: b1,   t . t'' = -|t'|^2 =: b2.
        b1 = x - 2 * eps_dot[:, None] * tan_dot
        b2 = -jnp.sum(tan_dot * tan_dot, -1)
        one_eps = 1 + eps
        tt = jnp.sum(tan * tan, -1)
        eps_dd = (jnp.sum(tan * b1, -1) - one_eps * b2) / tt
        tan_dd = (b1 - eps_dd[:, None] * tan) / one_eps[:, None]
        return jnp.concatenate(
            [eps_dot[:, None], tan_dot, eps_dd[:, None], tan_dd], axis=1
        )

    def constraint_error(self, y):
        _, t, _, _ = self._split(y)
        return jnp.max(jnp.abs(safe_norm(t) - 1.0))

    def project(self, y):
        """Nearest state with |t| = 1 and t . t' = 0 (node by node)."""
        eps, t, eps_dot, t_dot = self._split(y)
        t = t / safe_norm(t, keepdims=True)
        t_dot = t_dot - jnp.sum(t_dot * t, -1, keepdims=True) * t
        return jnp.concatenate([eps[:, None], t, eps_dot[:, None], t_dot], axis=1)

    def kinetic_energy(self, y):
        eps, t, eps_dot, t_dot = self._split(y)
        q_dot = eps_dot[:, None] * t + (1 + eps)[:, None] * t_dot
        return _natural_kinetic_energy(self, q_dot)

    def constant_load_potential(self, y, loads):
        eps, t, _, _ = self._split(y)
        return _natural_load_potential(self, (1 + eps)[:, None] * t, loads)


class NaturalAngleString(_AbstractNaturalString):
    """String in natural variables: strain eps and tangent angle phi (2D).

    State `y`: shape `(k + 1, 4)`, row i = (eps_i, phi_i, eps_i', phi_i'), with
    t = (sin phi, -cos phi) (phi from the downward vertical) and n = dt/dphi:
    eps'' - (1 + eps) phi'^2 = x . t and (1 + eps) phi'' + 2 eps' phi' = x . n.
    The unit-length constraint holds by construction.
    """

    formulation: ClassVar[str] = "angle"
    projects: ClassVar[bool] = False

    def __check_init__(self):
        if self.dim != 2:
            raise ValueError(
                "`dim` must be 2 for the angle formulation; use formulation="
                f"'natural' for 3D (got dim={self.dim!r})."
            )

    def state_shape(self):
        return (self.k + 1, 4)

    def initial_state(self, theta0):
        n = self.k + 1
        z = jnp.zeros((n,))
        phi = jnp.full((n,), theta0, dtype=jnp.float64)
        return jnp.stack([z, phi, z, z], axis=1)

    def _tn(self, phi):
        s, c = jnp.sin(phi), jnp.cos(phi)
        return jnp.stack([s, -c], -1), jnp.stack([c, s], -1)

    def kinematics(self, y):
        eps, phi, eps_dot, phi_dot = y[:, 0], y[:, 1], y[:, 2], y[:, 3]
        t, n = self._tn(phi)
        h = self.l / self.k
        r_s = (1 + eps)[:, None] * t
        v_s = eps_dot[:, None] * t + ((1 + eps) * phi_dot)[:, None] * n
        return Kinematics(
            _cumtrapz_nodes(r_s, h), _cumtrapz_nodes(v_s, h), self.mu, self.m_s
        )

    def strain(self, y):
        return y[:, 0], y[:, 2]

    def vector_field(self, t, y, effects, env):
        loads, laws = split_effects(effects)
        eps, phi, eps_dot, phi_dot = y[:, 0], y[:, 1], y[:, 2], y[:, 3]
        tan, nrm = self._tn(phi)
        kin = self.kinematics(y) if loads else None
        N = apply_laws(laws, self.EA, eps, eps_dot)
        x = _natural_x(self, t, kin, tan, N, loads, env)
        eps_dd = jnp.sum(x * tan, -1) + (1 + eps) * phi_dot**2
        phi_dd = (jnp.sum(x * nrm, -1) - 2 * eps_dot * phi_dot) / (1 + eps)
        return jnp.stack([eps_dot, phi_dot, eps_dd, phi_dd], axis=1)

    def kinetic_energy(self, y):
        eps, phi, eps_dot, phi_dot = y[:, 0], y[:, 1], y[:, 2], y[:, 3]
        t, n = self._tn(phi)
        q_dot = eps_dot[:, None] * t + ((1 + eps) * phi_dot)[:, None] * n
        return _natural_kinetic_energy(self, q_dot)

    def constant_load_potential(self, y, loads):
        t, _ = self._tn(y[:, 1])
        return _natural_load_potential(self, (1 + y[:, 0])[:, None] * t, loads)


FORMULATIONS = {
    "displacement": DisplacementString,
    "natural": NaturalTangentString,
    "angle": NaturalAngleString,
}
