"""The inextensible underwater tether: N point elements in 3D joined by massless links.

Source: O. Blintsov, "Development of the mathematical modeling method for dynamics of
the flexible tether as an element of the underwater complex", Eastern-European
Journal of Enterprise Technologies 1/7 (85), 2017, doi:10.15587/1729-4061.2017.90291
(sections 4-5, Table 1). Specification: specs/tether.md.

Geometry (0-based). Elements e_0..e_{N-1} are the points X_1..X_N of an extended chain
whose first point X_0 is the root (inboard) mount and whose last point X_{N+1} is the
running (fast) end mount. Link j = 0..N joins X_j and X_{j+1}; links 0 and N are the
end links. With the running end attached there are N + 1 links of nominal length
L_link = L/(N + 1) (paper section 4.4, "two additional links"); with a free running end
there are N links of L/N (link N is absent, its tension is 0). Each element stands for
l_e = L/N of cable (mass, volume and drag areas).

Link tensions T_j act along the unit link directions u_j (from X_j to X_{j+1}); the
element equation is eq 1, mu a_k = T_k u_k - T_{k-1} u_{k-1} + F_ext(k), with
mu = m_e + C_a rho Q_e (added mass). Three final classes differ only in how T comes
about (the tension method is structure, chosen by the class):

* ``AceamTether``: the paper's inverse-dynamics regulator (section 4.4). The constant
  tridiagonal system of the 1-D axial model is factorised once in closed form
  (``_aceam_solve``); the end links are proportional links of stiffness k.
* ``ExactTether``: exact constraint tensions from the second derivative of every
  link-length constraint with the true link directions, a symmetric tridiagonal
  system solved in O(N) per evaluation (Thomas algorithm, ``lax.scan``), with
  Baumgarte stabilisation. End links rigid (fixed or prescribed ends) or springs.
* ``LmsTether``: lumped masses and linear (optionally damped) springs on every link.

Ends: ``FixedEnd``, ``PrescribedEnd`` (piecewise-linear schedule of positions,
optionally smoothed), ``CoupledEnd`` (kinematics supplied by a vessel model through
``rates``; returns the end forces) and, for the running end, ``FreeEnd``.

Pay-out / haul-in (section 4.5): the released length L_r(t) is a
``PiecewiseLinear`` schedule; link targets are g_j = clip(L_link (j + 1) - L_c, 0,
L_link) with L_c = L - L_r the coiled length. Coiled elements are masked (static
shapes, no re-factorisation): they take the root mount's kinematics, get no external
force, and their stored state relaxes to the mount (time constant 0.05 s) so that they
re-enter the computation where the cable leaves the drum.

State layout: node-major, shape ``(N, 6)``, row n = (p_n, v_n) (m, m/s), so the
Jacobian of the vector field is block-banded.
"""

import abc
import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._arrays import FloatScalar, dot as _dot, f64, param as _param
from .._model import AbstractModel, SolverStructure
from .._programs import eager_jit
from .._validate import (
    check_int,
    check_nonnegative,
    check_positive,
    check_shape,
    is_concrete,
)
from ..chain import (
    AbstractChainLoad,
    AbstractEnd,
    Buoyancy,
    ChainKinematics,
    CoupledEnd,
    Drag,
    EndKinematics,
    FixedEnd,
    FreeEnd,
    Gravity,
    PiecewiseLinear,
    links,
)


# Inactive (coiled) elements relax to the drum with this time constant, s: slow
# enough not to stiffen an explicit method, fast enough that an element hauled in is
# back on the drum long before it is paid out again.
_DRUM_RELAXATION = 0.05

# ExactTether with a rigid root: the partial link's element leaves the computation
# when its link is this fraction of L_link long (and joins it at that length).
_JOIN_FRACTION = 0.02


# ---------------------------------------------------------------------------
# Tension solvers


def thomas(sub, diag, sup, rhs):
    """Solve a tridiagonal system in O(n) (Thomas algorithm, two `lax.scan`s).

    Row i reads sub[i] x[i-1] + diag[i] x[i] + sup[i] x[i+1] = rhs[i] (sub[0] and
    sup[-1] are ignored). No pivoting: the tether systems are diagonally dominant.
    """
    sub = sub.at[0].set(0.0)

    def forward(carry, row):
        c_prev, d_prev = carry
        a, b, c, r = row
        den = b - a * c_prev
        c_new = c / den
        d_new = (r - a * d_prev) / den
        return (c_new, d_new), (c_new, d_new)

    zero = jnp.zeros((), rhs.dtype)
    _, (cp, dp) = jax.lax.scan(forward, (zero, zero), (sub, diag, sup, rhs))

    def backward(x_next, row):
        c, d = row
        x = d - c * x_next
        return x, x

    _, x = jax.lax.scan(backward, zero, (cp, dp), reverse=True)
    return x


def _aceam_solve(rhs, start):
    """Solve the ACEAM axial system for the regulated links, factorised once.

    The 1-D inverse model (paper eqs 5-6) with uniform element inertia mu reduces to
    w (T_{i-1} - 2 T_i + T_{i+1}) = rhs_i, w = 1/mu, over the regulated links, with
    the end-link forces already in rhs. Here the caller passes rhs * mu, so this
    solves A T = rhs for A = tridiag(1, -2, 1) (size n), restricted to the trailing
    rows i >= start (the links still paid out) with T_{start-1} = T_n = 0.

    A is constant, so its backward (UL) factorisation is known in closed form: the
    pivots are -(k + 2)/(k + 1) at distance k from the last row. Substituting gives two
    cumulative sums (no matrix, O(n), vectorised), and the trailing principal
    submatrix of A has the trailing part of the same factors, so paying out or hauling
    in needs no re-factorisation (paper section 4.5: "B need not be re-inverted").
    """
    n = rhs.shape[0]
    i = jnp.arange(n)
    m = n - i  # = k + 1 with k the distance from the last row
    S = jnp.cumsum((m * rhs)[::-1])[::-1]  # S_i = sum_{i' >= i} (n - i') rhs_i'
    terms = S / ((m + 1) * m)
    if start is not None:
        terms = jnp.where(i >= start, terms, 0.0)
    Y = -jnp.cumsum(terms)
    return m * Y


# ---------------------------------------------------------------------------
# The chain


class _Chain(eqx.Module):
    """Everything the tension methods share, for one state (not user-facing)."""

    P: Array  # effective element positions (N, 3)
    V: Array  # effective element velocities (N, 3)
    u: Array  # unit link directions (N + 1, 3)
    l: Array  # link lengths (N + 1,)
    ldot: Array  # link length rates (N + 1,)
    dV: Array  # relative velocities of the link ends (N + 1, 3)
    g: Array  # target lengths (N + 1,)
    gdot: Array
    gddot: Array
    r: Array  # index of the root link (int scalar)
    active: Array | None  # elements in the computation (N,) bool, None = all
    tangents: Array  # element axes i_n (N, 3)
    F_ext: Array  # external loads on the elements (N, 3)
    kin: ChainKinematics
    inertia: Array  # element inertia mu, kg
    root: EndKinematics
    fast: EndKinematics | None
    released: Array  # released length L_r, m
    payout: Array  # pay-out speed dL_r/dt, m/s


class AbstractTether(AbstractModel):
    """An inextensible tether of N point elements (see the module docstring).

    **Fields** (all final classes): `L` full length (m), `d` diameter (m),
    `mass_per_length` (kg/m), `added_mass` coefficient C_a (-), array leaves (the
    water density is the scene's `Environment.rho_water`); `N` (number of
    elements), `root`, `fast` (end conditions) and `released` (a `PiecewiseLinear`
    released length L_r(t), m, or `None` for a fixed length) are structure.
    """

    L: FloatScalar = _param()
    d: FloatScalar = _param()
    mass_per_length: FloatScalar = _param()
    added_mass: FloatScalar = _param(default=1.0)
    N: int = eqx.field(static=True, default=101)
    root: AbstractEnd = eqx.field(default_factory=lambda: FixedEnd(jnp.zeros(3)))
    fast: AbstractEnd = eqx.field(default_factory=FreeEnd)
    released: PiecewiseLinear | None = None
    method: ClassVar[str]
    projects: ClassVar[bool] = False
    accepts: ClassVar[tuple[type, ...]] = (Gravity, Buoyancy, AbstractChainLoad)
    preset_system: ClassVar[str] = "tether"

    def __check_init__(self):
        _check_tether(self)

    def structure(self, effects):
        """Dense: the link tensions are solved over the whole chain at once
        (ACEAM's axial model, the exact constraints), so every node's rate depends
        on every other's state; the solvers skip probing for a band."""
        del effects
        return SolverStructure(dense=True)

    def _end_link_energy(self, ch):
        """Elastic energy of the proportional end links (stiffness `k`, N)."""
        onehot = self._root_onehot(ch)
        stretch = ch.l - ch.g
        e = 0.5 * self.k / self.link_length * jnp.sum(onehot * stretch**2)
        if self.fast.attached:
            e = e + 0.5 * self.k / self.link_length * stretch[-1] ** 2
        return e

    # -- derived sizes (properties of the parameters, so they stay differentiable)
    @property
    def n_links(self) -> int:
        """Number of links of the full cable: N + 1 (running end attached) or N."""
        return self.N + 1 if self.fast.attached else self.N

    @property
    def link_length(self):
        """Nominal link length L_link = L / n_links, m."""
        return self.L / self.n_links

    @property
    def element_length(self):
        """Length of cable one element stands for, l_e = L/N, m."""
        return self.L / self.N

    @property
    def element_volume(self):
        """Displaced volume of one element, Q = pi d^2/4 l_e, m^3."""
        return 0.25 * jnp.pi * self.d**2 * self.element_length

    @property
    def element_mass(self):
        """Mass of one element, kg."""
        return self.mass_per_length * self.element_length

    def inertia(self, env):
        """mu = m_e + C_a rho Q_e: element mass plus added mass of water (density
        `env.rho_water`), kg."""
        return self.element_mass + self.added_mass * env.rho_water * self.element_volume

    # Pay-out and haul-in. 0: the paper's scheme (section 4.5): the partial link
    # shrinks to zero length, and the element before it sits at the mount on a
    # zero-length root link. phi > 0: the partial link is the root link, its target
    # within (phi, 1 + phi] L_link; its element leaves the computation when the
    # link is phi L_link long (hauling in) and joins it at that length (paying out).
    _join_fraction: ClassVar[float] = 0.0

    @abc.abstractmethod
    def _tensions(self, ch: _Chain) -> Array:
        """Link tensions T_j, j = 0..N, N (0 for inactive and absent links)."""

    @abc.abstractmethod
    def _elastic_energy(self, ch: _Chain) -> Array:
        """Energy stored in the elastic links, J."""

    def state_shape(self):
        return (self.N, 6)

    def project(self, y):
        return y

    # -- geometry
    def _schedule(self, t):
        """(L_c, dL_c/dt, d2L_c/dt2, L_r) at time t; L_c = 0 for a fixed length."""
        if self.released is None:
            zero = jnp.zeros((), jnp.float64)
            return zero, zero, zero, self.L + zero
        L_r, rate, accel = self.released.kinematics(t)
        return self.L - L_r, -rate, -accel, L_r

    def _targets(self, t):
        """Targets g_j, their rates, the root link index r and the coiled-index q."""
        j = jnp.arange(self.N + 1)
        exists = j < self.n_links
        L_link = self.link_length
        L_c, L_c_dot, L_c_ddot, L_r = self._schedule(t)
        if self.released is None:
            g = jnp.where(exists, L_link, 0.0)
            zeros = jnp.zeros(self.N + 1)
            return g, zeros, zeros, jnp.zeros((), jnp.int32), L_r, L_c_dot
        # The partly released link q has target raw_q in (phi, 1 + phi] L_link,
        # phi = `_join_fraction`: links j < q are on the drum, links j > q full.
        phi = self._join_fraction
        q = jnp.clip(jnp.floor(L_c / L_link + phi).astype(jnp.int32), 0, self.N - 1)
        raw = L_link * (j + 1) - L_c
        partial = (j == q) & exists
        g = jnp.where(j < q, 0.0, jnp.where(partial, raw, L_link))
        g = jnp.where(exists, g, 0.0)
        gdot = jnp.where(partial, -L_c_dot, 0.0)
        gddot = jnp.where(partial, -L_c_ddot, 0.0)
        # phi > 0: the partial link q joins the mount to element q, and elements
        # < q are on the drum. phi = 0 (the paper): the element q - 1 sits at the
        # mount on a zero-length proportional link, the partial link q is
        # regulated, elements < q - 1 are on the drum.
        r = q if self._join_fraction else jnp.maximum(q - 1, 0)
        return g, gdot, gddot, r, L_r, -L_c_dot

    def _chain(self, t, y, effects, env, root, fast) -> _Chain:
        loads = _loads(effects)
        p, v = y[:, :3], y[:, 3:]
        root = self.root.kinematics(t) if root is None else root
        if self.fast.attached:
            fast = self.fast.kinematics(t) if fast is None else fast
        else:
            fast = None
        g, gdot, gddot, r, L_r, payout = self._targets(t)
        if self.released is None:
            active = None
            P, V = p, v
        else:
            active = jnp.arange(self.N) >= r
            P = jnp.where(active[:, None], p, root.position)
            V = jnp.where(active[:, None], v, root.velocity)
        if fast is None:
            X = jnp.concatenate([root.position[None], P, P[-1:]], axis=0)
            XV = jnp.concatenate([root.velocity[None], V, V[-1:]], axis=0)
        else:
            X = jnp.concatenate([root.position[None], P, fast.position[None]], axis=0)
            XV = jnp.concatenate([root.velocity[None], V, fast.velocity[None]], axis=0)
        u, l, ldot, dV = links(X[:-1], X[1:], XV[:-1], XV[1:])
        if fast is None:
            tangents = jnp.concatenate([u[1:-1], u[-2:-1]], axis=0)
        else:
            tangents = u[1:]
        each = lambda x: jnp.broadcast_to(x, (self.N,))
        kin = ChainKinematics(
            positions=P,
            velocities=V,
            tangents=tangents,
            mass=each(self.element_mass),
            volume=each(self.element_volume),
            length=each(self.element_length),
            wetted_length=each(self.element_length),
            diameter=each(self.d),
        )
        F_ext = jnp.zeros_like(P)
        for effect in loads:
            F_ext = F_ext + effect.forces(t, kin, env).nodes
        if active is not None:
            F_ext = jnp.where(active[:, None], F_ext, 0.0)
        return _Chain(
            P=P,
            V=V,
            u=u,
            l=l,
            ldot=ldot,
            dV=dV,
            g=g,
            gdot=gdot,
            gddot=gddot,
            r=r,
            active=active,
            tangents=tangents,
            F_ext=F_ext,
            kin=kin,
            inertia=self.inertia(env),
            root=root,
            fast=fast,
            released=L_r,
            payout=payout,
        )

    def _spring(self, ch, k, j):
        """Tension of a proportional link: k (l - g)/L_link (paper section 4.3)."""
        return k * (ch.l[j] - ch.g[j]) / self.link_length

    def _root_onehot(self, ch):
        if self.released is None:
            return jnp.zeros(self.N + 1).at[0].set(1.0)
        return (jnp.arange(self.N + 1) == ch.r).astype(jnp.float64)

    def _end_forces(self, ch, T):
        """Forces of the tether on the root and running-end mounts, N."""
        root_force = jnp.sum((self._root_onehot(ch) * T)[:, None] * ch.u, axis=0)
        fast_force = -T[-1] * ch.u[-1]
        return root_force, fast_force

    # -- dynamics
    def rates(self, t, y, effects, env, root=None, fast=None):
        """dy/dt and the end forces; the coupling interface for vessel models.

        **Arguments:**

        - `t`: time, s. `y`: state `(N, 6)`. `effects`, `env`: the scene's effects
          and environment.
        - `root`, `fast`: `EndKinematics` of the mounts, overriding the model's end
          conditions (required for a `CoupledEnd`).

        **Returns:** `(dy/dt, root_force, fast_force)`: the forces (N, shape `(3,)`)
        that the tether exerts on the root and running-end mounts.
        """
        ch = self._chain(t, y, effects, env, root, fast)
        T = self._tensions(ch)
        Tu = T[:, None] * ch.u
        acc = (Tu[1:] - Tu[:-1] + ch.F_ext) / ch.inertia
        if ch.active is None:
            dy = jnp.concatenate([ch.V, acc], axis=1)
        else:
            p, v = y[:, :3], y[:, 3:]
            rk = ch.root
            drum, v_drum, a_drum = rk.position, rk.velocity, rk.acceleration
            if self._join_fraction:
                # Elements on the drum follow the point one link length behind the
                # root link's element, on the root link's line: the next element
                # to be paid out arrives at phi L_link from the mount (plus a
                # spring root's stretch, so that the spring keeps its tension)
                # with the cable's velocity, on the line of the link it splits.
                onehot = self._root_onehot(ch)
                u_root = jnp.sum(onehot[:, None] * ch.u, axis=0)
                at_root = onehot[: self.N, None]
                drum = jnp.sum(at_root * ch.P, axis=0) - self.link_length * u_root
                v_drum = jnp.sum(at_root * ch.V, axis=0)
                a_drum = jnp.sum(at_root * acc, axis=0)
            dp_drum = v_drum + (drum - p) / _DRUM_RELAXATION
            dv_drum = a_drum + (v_drum - v) / _DRUM_RELAXATION
            act = ch.active[:, None]
            dy = jnp.concatenate(
                [jnp.where(act, ch.V, dp_drum), jnp.where(act, acc, dv_drum)], axis=1
            )
        root_force, fast_force = self._end_forces(ch, T)
        return dy, root_force, fast_force

    def vector_field(self, t, y, effects, env):
        return self.rates(t, y, effects, env)[0]

    def observables(self, t, y, effects, env):
        """Positions (N, 3), velocities, mount-and-element points `nodes` (N + 2, 3),
        link `tension` (N + 1,), link `strain` (l - g)/L_link, `length_error`
        (L_r - sum of link lengths)/L_r, `released_length`, `root_force` and
        `fast_force` (on the mounts, (3,)), `energy` (kinetic + potentials of the
        conservative loads + elastic links) and `constraint_error`
        (max |l - g|/L_link)."""
        ch = self._chain(t, y, effects, env, None, None)
        T = self._tensions(ch)
        root_force, fast_force = self._end_forces(ch, T)
        fast_point = ch.P[-1] if ch.fast is None else ch.fast.position
        nodes = jnp.concatenate(
            [ch.root.position[None], ch.P, fast_point[None]], axis=0
        )
        strain = (ch.l - ch.g) / self.link_length
        total = jnp.sum(ch.g)
        return {
            "positions": ch.P,
            "velocities": ch.V,
            "nodes": nodes,
            "tension": T,
            "strain": strain,
            "length_error": (total - jnp.sum(ch.l)) / total,
            "released_length": ch.released,
            "root_force": root_force,
            "fast_force": fast_force,
            "energy": self._energy(ch, effects, env),
            "constraint_error": jnp.max(jnp.abs(strain)),
        }

    def _energy(self, ch, effects, env):
        # Elements on the winch drum are out of the computation: no energy.
        weights = jnp.ones(self.N) if ch.active is None else ch.active * 1.0
        ke = 0.5 * ch.inertia * jnp.sum(weights * _dot(ch.V, ch.V))
        pot = jnp.zeros(())
        for effect in _loads(effects):
            if effect.constant:  # potential: minus the work of the constant force
                work = _dot(effect.forces(0.0, ch.kin, env).nodes, ch.P)
                pot = pot - jnp.sum(weights * work)
        return ke + pot + self._elastic_energy(ch)

    def energy(self, y, effects, env, t=0.0):
        """Total mechanical energy of state `y`, J."""
        return self._energy(self._chain(t, y, effects, env, None, None), effects, env)


def _loads(effects):
    for e in effects:
        if not isinstance(e, AbstractTether.accepts):
            raise ValueError(
                f"the tether takes chain loads (Gravity, Buoyancy, Drag); got "
                f"{type(e).__name__} in `effects`."
            )
    return tuple(effects)


def _check_tether(model: AbstractTether) -> None:
    check_int("N", model.N, 2)
    for name in ("L", "d", "mass_per_length", "added_mass"):
        check_shape(name, getattr(model, name), ())
    check_positive("L", model.L, "m")
    check_positive("d", model.d, "m")
    check_positive("mass_per_length", model.mass_per_length, "kg/m")
    check_nonnegative("added_mass", model.added_mass)
    if not isinstance(model.root, AbstractEnd) or isinstance(model.root, FreeEnd):
        raise ValueError(
            "`root` must be a FixedEnd, PrescribedEnd or CoupledEnd (the inboard end "
            f"is always held); got {model.root!r}."
        )
    if not isinstance(model.fast, AbstractEnd):
        raise ValueError(
            f"`fast` must be a jaxstring end condition; got {model.fast!r}."
        )
    rel = model.released
    if rel is not None:
        if not isinstance(rel, PiecewiseLinear) or jnp.ndim(rel.values) != 1:
            raise ValueError(
                "`released` must be a PiecewiseLinear schedule of the released length "
                "(values shape (K,), m) or None."
            )
        if is_concrete(rel.values) and is_concrete(model.L):
            vals = np.asarray(rel.values)
            L = float(model.L)
            L_link = L / model.n_links
            if np.any(vals > L * (1 + 1e-12)):
                raise ValueError(
                    f"`released` length must not exceed the full length L = {L:g} m; "
                    f"got up to {vals.max():g} m."
                )
            if np.any(vals < 2 * L_link):
                raise ValueError(
                    f"`released` length must stay >= 2 link lengths "
                    f"({2 * L_link:g} m); got down to {vals.min():g} m."
                )


# ---------------------------------------------------------------------------
# The three tension methods


class AceamTether(AbstractTether):
    """Tether with the paper's ACEAM regulator (inverse dynamics, section 4.4).

    Reference model of each regulated link length l_m with target g_m:
    a_m = ((g_m - l_m)/T - dl_m/dt)/T1 (critically damped at the paper's
    T = 0.1 s, T1 = 0.025 s). The 1-D axial model
    mu a_d(n) = F_T(n) - F_T(n-1) + F_ext,s(n),
    a_d(m+1) - a_d(m) = a_m (external forces projected on each element's axis i_n)
    gives the tensions, which then act along the links in 3-D. End links are
    proportional links F = k (l - g)/L_link.

    **Arguments:** as `AbstractTether`, plus `T`, `T1` (s), `k` (end-link stiffness,
    N; Table 1: 10000 N) and `feedforward` (structure): apply the reference model
    to the tracking error e = l - g, e'' = -(e/T + e')/T1, i.e.
    a_m = g'' + ((g - l)/T + g' - l')/T1. It equals the paper's law wherever the
    target is constant and removes the steady lag l - g = -T g' (0.05 m at 0.5 m/s)
    of the link being paid out or hauled in (False: the law as printed; the
    `tether_winch` scene uses True).

    The fixed-length error (L_r - L_a)/L_r is the stretch of the two proportional
    end links, (|F_root| + |F_fast|) L_link/(k L_r), to within ~3e-5 (the regulated
    links' errors cancel in the sum): it measures the end forces, not the regulator.
    """

    T: FloatScalar = _param(default=0.1)
    T1: FloatScalar = _param(default=0.025)
    k: FloatScalar = _param(default=1e4)
    feedforward: bool = eqx.field(static=True, default=False)
    method: ClassVar[str] = "aceam"

    def __check_init__(self):
        check_positive("T", self.T, "s")
        check_positive("T1", self.T1, "s")
        check_positive("k", self.k, "N")

    def _tensions(self, ch):
        N = self.N
        onehot = self._root_onehot(ch)
        T_root = jnp.sum(onehot * self._spring(ch, self.k, slice(None)))
        T_fast = self._spring(ch, self.k, N) if self.fast.attached else 0.0
        # Axial projections of the external loads and of the end-link forces.
        f = _dot(ch.F_ext, ch.tangents)
        u_next = ch.u[1:]  # axis of element m is u_{m+1}
        root_on_first = -T_root * _dot(ch.u[:-1], u_next)  # on element m = r
        f = f + onehot[:-1] * root_on_first
        f = f.at[-1].add(T_fast)
        # Reference model of the regulated links j = 1..N-1.
        g, l, ld = ch.g[1:N], ch.l[1:N], ch.ldot[1:N]
        alpha = ((g - l) / self.T - ld) / self.T1
        if self.feedforward:
            alpha = alpha + ch.gddot[1:N] + ch.gdot[1:N] / self.T1
        rhs = alpha - (f[1:] - f[:-1]) / ch.inertia
        start = None if self.released is None else ch.r
        T_reg = ch.inertia * _aceam_solve(rhs, start)
        T = jnp.concatenate([jnp.zeros(1), T_reg, jnp.zeros(1)])
        T = T + onehot * T_root
        return T.at[N].add(T_fast)

    def _elastic_energy(self, ch):
        return self._end_link_energy(ch)


class ExactTether(AbstractTether):
    """Tether with exact constraint tensions.

    Each rigid link keeps l_j = g_j(t) through its second derivative with the true
    link directions, l_j'' = u_j . (a_{j+1} - a_j) + (|dv_j|^2 - (l_j')^2)/l_j, set to
    g'' + 2 omega (g' - l') + omega^2 (g - l) (Baumgarte: drift decays critically
    damped at rate omega). With the element equations this is a tridiagonal system
    for the tensions, symmetric for all-rigid links, solved in O(N) per evaluation
    (`thomas`); valid at any bending angle.

    **Arguments:** as `AbstractTether`, plus `omega` (Baumgarte rate, 1/s),
    `end_links` (structure): `"rigid"` (end links are constraints too) or
    `"spring"` (proportional links of stiffness `k`, N, as in ACEAM; required with a
    `CoupledEnd`).
    """

    omega: FloatScalar = _param(default=20.0)
    k: FloatScalar = _param(default=1e4)
    end_links: str = eqx.field(static=True, default="rigid")
    method: ClassVar[str] = "exact"

    def __check_init__(self):
        check_positive("omega", self.omega, "1/s")
        check_positive("k", self.k, "N")
        if self.end_links not in ("rigid", "spring"):
            raise ValueError(
                f"`end_links` must be 'rigid' or 'spring'; got {self.end_links!r}."
            )
        if self.end_links == "rigid" and (
            isinstance(self.root, CoupledEnd) or isinstance(self.fast, CoupledEnd)
        ):
            raise ValueError(
                "`end_links` must be 'spring' with a CoupledEnd (a rigid link to a "
                "vessel would need the vessel's mass inside the tension system)."
            )

    # The exact constraint of a link holds a 1/l (centripetal) term: the partial
    # link never gets shorter than this fraction of L_link.
    _join_fraction: ClassVar[float] = _JOIN_FRACTION

    def _tensions(self, ch):
        N = self.N
        w = 1.0 / ch.inertia
        if ch.active is None:
            w_el = jnp.full(N, w)
            acc_el = ch.F_ext * w
        else:
            w_el = jnp.where(ch.active, w, 0.0)
            acc_el = jnp.where(ch.active[:, None], ch.F_ext * w, ch.root.acceleration)
        zero = jnp.zeros(1)
        w_ext = jnp.concatenate([zero, w_el, zero])
        a_fast = jnp.zeros(3) if ch.fast is None else ch.fast.acceleration
        acc0 = jnp.concatenate(
            [ch.root.acceleration[None], acc_el, a_fast[None]], axis=0
        )
        wl, wr = w_ext[:-1], w_ext[1:]  # nodes j and j + 1 of link j
        cos = _dot(ch.u[:-1], ch.u[1:])  # u_j . u_{j+1}, j = 0..N-1
        sub = wl * jnp.concatenate([zero, cos])
        sup = wr * jnp.concatenate([cos, zero])
        diag = -(wl + wr)
        l_safe = jnp.maximum(ch.l, 1e-9 * self.link_length)
        centripetal = (_dot(ch.dV, ch.dV) - ch.ldot**2) / l_safe
        om = self.omega
        beta = ch.gddot + 2 * om * (ch.gdot - ch.ldot) + om**2 * (ch.g - ch.l)
        rhs = beta - centripetal - _dot(ch.u, acc0[1:] - acc0[:-1])
        # Rows with a known tension: links on the drum (T = 0), spring end links,
        # and the absent link of a free end.
        j = jnp.arange(N + 1)
        known = jnp.zeros(N + 1)
        ident = j < ch.r if ch.active is not None else jnp.zeros(N + 1, bool)
        if self.end_links == "spring":
            onehot = self._root_onehot(ch)
            known = known + onehot * self._spring(ch, self.k, slice(None))
            ident = ident | (onehot > 0)
        if not self.fast.attached:
            ident = ident | (j == N)
        elif self.end_links == "spring":
            known = known.at[N].set(self._spring(ch, self.k, N))
            ident = ident | (j == N)
        sub = jnp.where(ident, 0.0, sub)
        sup = jnp.where(ident, 0.0, sup)
        diag = jnp.where(ident, 1.0, diag)
        rhs = jnp.where(ident, known, rhs)
        return thomas(sub, diag, sup, rhs)

    def _elastic_energy(self, ch):
        if self.end_links == "rigid":
            return jnp.zeros(())
        return self._end_link_energy(ch)


class LmsTether(AbstractTether):
    """Lumped masses and springs: every link is a proportional (linear) spring,
    T = k (l - g)/L_link + c (l' - g')/L_link, tension and compression (paper
    section 4.3 and 5.2: k_lms = 40 k_aceam for ACEAM's length accuracy).

    **Arguments:** as `AbstractTether`, plus `k` (N) and `c` (damping, N s; >= 0).
    """

    k: FloatScalar = _param(default=4e5)
    c: FloatScalar = _param(default=0.0)
    method: ClassVar[str] = "lms"

    def __check_init__(self):
        check_positive("k", self.k, "N")
        check_nonnegative("c", self.c, "N s")

    def structure(self, effects):
        """Band 1 under jaxstring's own chain effects (each link's spring and drag
        act on its two nodes; None: detect, under any other load);
        tests/solvers/test_fast_solvers.py checks it against detection."""
        local = all(type(e) in (Gravity, Buoyancy, Drag) for e in effects)
        return SolverStructure(bandwidth=1 if local else None)

    def _mask(self, ch):
        j = jnp.arange(self.N + 1)
        mask = j < self.n_links
        if ch.active is not None:
            mask = mask & (j >= ch.r)
        return mask

    def _tensions(self, ch):
        T = (self.k * (ch.l - ch.g) + self.c * (ch.ldot - ch.gdot)) / self.link_length
        return jnp.where(self._mask(ch), T, 0.0)

    def _elastic_energy(self, ch):
        stretch = jnp.where(self._mask(ch), ch.l - ch.g, 0.0)
        return 0.5 * self.k / self.link_length * jnp.sum(stretch**2)


TETHER_METHODS = {
    "aceam": AceamTether,
    "exact": ExactTether,
    "lms": LmsTether,
}


# ---------------------------------------------------------------------------
# Initial shapes (construction time, NumPy; not traced)


@eager_jit(tiered=True)
def _mounts(model, t0):
    """Target link lengths and the mount positions at `t0`, in one compiled call."""
    root = model.root.kinematics(t0).position
    fast = model.fast.kinematics(t0).position if model.fast.attached else root
    return model._targets(t0)[0], root, fast


def _rest_geometry(model, t0):
    """(target lengths of the links, root mount position, running-end mount
    position) at `t0`, as NumPy arrays."""
    g, a, b = (np.asarray(x) for x in _mounts(model, f64(t0)))
    return g[: model.n_links], a, b


def arc_state(model: AbstractTether, bulge=(-1.0, 0.0, 0.0), t0: float = 0.0):
    """A state at rest with every link at its target length, on a circular arc.

    The elements form an equal-chord polygon (chords g_j) inscribed in a circle
    through both mount points, bulging towards `bulge` (paper section 5.1 gives no
    initial shape; the line settles during the first 10 s). Needs an attached running
    end, and the released length longer than the distance between the mounts.

    **Returns:** state `(N, 6)`.
    """
    if not model.fast.attached:
        raise ValueError(
            "`arc_state` needs an attached running end; use hanging_state."
        )
    g, a, b = _rest_geometry(model, t0)
    D = float(np.linalg.norm(b - a))
    Ltot = float(g.sum())
    if not D < Ltot * (1 - 1e-9):
        raise ValueError(
            f"the released length {Ltot:g} m must exceed the distance between the "
            f"mounts {D:g} m for an arc shape."
        )
    e1 = (b - a) / D
    e2 = np.asarray(bulge, float) - np.dot(bulge, e1) * e1
    if np.linalg.norm(e2) < 1e-12:
        raise ValueError("`bulge` must not be parallel to the line between the mounts.")
    e2 = e2 / np.linalg.norm(e2)
    gmax = g.max()

    def angles(R):
        return 2 * np.arcsin(np.minimum(g / (2 * R), 1.0))

    # Smallest radius with total angle <= 2 pi, then bisect the chord on [lo, hi]
    # (the chord of an arc of given length falls monotonically with its angle).
    lo, hi = gmax / 2, 1e6 * Ltot
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if angles(mid).sum() > 2 * math.pi:
            lo = mid
        else:
            hi = mid
    lo, hi = hi, 1e6 * Ltot
    for _ in range(300):
        mid = math.sqrt(lo * hi)
        theta = angles(mid).sum()
        if 2 * mid * math.sin(theta / 2) < D:
            lo = mid
        else:
            hi = mid
    R = math.sqrt(lo * hi)
    th = angles(R)
    Theta = th.sum()
    centre = np.array([D / 2, -R * math.cos(Theta / 2)])
    phi = (Theta + math.pi) / 2 - np.concatenate([[0.0], np.cumsum(th)])
    xy = centre[None] + R * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    pts = a[None] + xy[:, :1] * e1[None] + xy[:, 1:] * e2[None]
    pos = pts[1 : model.N + 1]
    return jax.device_put(np.concatenate([pos, np.zeros_like(pos)], axis=1))


def hanging_state(model: AbstractTether, direction=(0.0, 0.0, -1.0), t0: float = 0.0):
    """A state at rest: a straight line from the root mount along `direction`, every
    link at its target length (the running end must be free).

    **Returns:** state `(N, 6)`.
    """
    if model.fast.attached:
        raise ValueError("`hanging_state` needs a FreeEnd running end.")
    g, a, _ = _rest_geometry(model, t0)
    e = np.asarray(direction, float)
    e = e / np.linalg.norm(e)
    s = np.cumsum(g)[: model.N]
    pos = a[None] + s[:, None] * e[None]
    return jax.device_put(np.concatenate([pos, np.zeros_like(pos)], axis=1))
