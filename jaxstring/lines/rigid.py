"""Rigid objects of a mooring network: frames, prescribed motions, and the
equations of motion of rods (and bodies) with the lines on them.

Every rigid object moves with a frame: its origin (a rod's end A, a body's
reference point) and orientation R (body to earth). A frame's translation and
rotation are each

- fixed (the earth, a fixed rod),
- prescribed (a `RigidMotion`: a table or a function of time),
- taken from a parent frame (a rod pinned to a body: its end A moves with the
  body, its rotation is its own), or
- free: state.

Free rotations are unit quaternions q (scalar first), with dq/dt = 1/2 (0, omega)
x q for the angular velocity omega in earth axes: no Euler-angle singularity.

**Equations of motion.** A group is a frame with free degrees of freedom and the
frames pinned to it. Everything in it is lumped masses M_k (3 x 3, added mass
included) at points with forces F_k, and rotational inertias I_e with moments
tau_e. Each point's acceleration is affine in the group's generalised
accelerations u': a_k = J_k u' + c_k (c_k: the centripetal terms and the
prescribed accelerations), and each frame's angular acceleration likewise,
alpha_e = Jw_e u' + cw_e. The group's equations (d'Alembert, virtual power) are

    (sum_k J_k^T M_k J_k + sum_e Jw_e^T I_e Jw_e) u'
        = sum_k J_k^T (F_k - M_k c_k) + sum_e Jw_e^T (tau_e - w_e x I_e w_e - I_e cw_e),

J and c taken by forward-mode differentiation of the accelerations, which are
written once. This is exact rigid-body mechanics, gyroscopic terms included;
MoorDyn 2.7 leaves out w x I w, and a rod pinned to a body enters both its own
and the body's equations there (`docs/lines.md`).

**State rows** (node-major `(n, 6)`, with the lines' nodes): a free translation
is one row (position, velocity); a free rotation two rows, (q_x, q_y, q_z,
omega) and (q_w, 0, 0, 0, 0, 0).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .._arrays import f64 as _f64
from .._linalg.banded import pivoted_solve
from ..chain import PiecewiseLinear
from .bodies import quat_multiply, rotation_matrix


# ---------------------------------------------------------------------------
# Rotations (quaternions scalar first; `jaxstring.lines.bodies`)


def quat_rate(q, omega):
    """dq/dt = 1/2 (0, omega) x q, omega in earth axes."""
    return 0.5 * quat_multiply(jnp.concatenate([jnp.zeros(1), omega]), q)


def _vee(S):
    return jnp.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2


# ---------------------------------------------------------------------------
# Prescribed motion


class Frame(eqx.Module):
    """Kinematics of a frame: origin `position`, `velocity`, `acceleration` (m,
    m/s, m/s^2), orientation `rotation` (3 x 3, body to earth), angular
    `omega` and `alpha` (rad/s, rad/s^2, earth axes)."""

    position: Array
    rotation: Array
    velocity: Array
    omega: Array
    acceleration: Array
    alpha: Array


class RigidMotion(eqx.Module):
    """A prescribed rigid motion: the pose offset `(dx, dy, dz, rx, ry, rz)` (m,
    rad) of a frame from its initial pose, as a table or a function of time.

    The frame's origin is at its initial position plus (dx, dy, dz); its
    orientation is R(rx, ry, rz) R_0 (MoorDyn's Euler angles,
    `bodies.rotation_matrix`),
    turned about the moving origin. Velocities and accelerations are the exact
    time derivatives (forward-mode autodiff), the angular velocity the one of
    R(t) (not the Euler-angle rates).

    **Arguments:** either `times` `(K,)` (s) and `poses` `(K, 6)` (a table,
    piecewise linear, optionally smoothed over `smoothing` s, see
    `PiecewiseLinear`), or `fn(t, params) -> (6,)` with its `params`.
    """

    table: PiecewiseLinear | None = None
    fn: object = eqx.field(static=True, default=None)
    params: object = None

    def __init__(self, times=None, poses=None, smoothing=0.0, fn=None, params=None):
        if fn is None:
            poses = _f64(poses)
            if poses.ndim != 2 or poses.shape[1] != 6:
                raise ValueError(
                    "`poses` must have shape (K, 6): dx dy dz (m), rx ry rz (rad) per "
                    f"time; got {poses.shape}."
                )
            self.table = PiecewiseLinear(times, poses, smoothing)
        elif not callable(fn):
            raise ValueError(f"`fn` must be callable; got {fn!r}.")
        self.fn = fn
        self.params = params

    def pose(self, t):
        """The pose offset `(6,)` at time `t`."""
        if self.fn is not None:
            return jnp.asarray(self.fn(t, self.params), jnp.float64)
        return self.table.value(t)

    def frame(self, t, position0, rotation0) -> Frame:
        """The frame at time `t` of a frame initially at `position0`,
        `rotation0`."""
        t = _f64(t)

        def pose_rate(s):
            return jax.jvp(self.pose, (s,), (jnp.ones_like(s),))

        (x, xd), (_, xdd) = jax.jvp(pose_rate, (t,), (jnp.ones_like(t),))

        def rot(a):
            return rotation_matrix(a) @ rotation0

        def omega_of(a, ad):
            R, Rd = jax.jvp(rot, (a,), (ad,))
            return _vee(Rd @ R.T)

        R = rot(x[3:])
        omega, alpha = jax.jvp(omega_of, (x[3:], xd[3:]), (xd[3:], xdd[3:]))
        return Frame(position0 + x[:3], R, xd[:3], omega, xdd[:3], alpha)


# ---------------------------------------------------------------------------
# Groups


class PointSet(eqx.Module):
    """Lumped masses moving with one frame of a group: positions `(K, 3)`,
    masses `(K, 3, 3)`, forces `(K, 3)`."""

    frame: int = eqx.field(static=True)
    positions: Array
    masses: Array
    forces: Array


class Rotational(eqx.Module):
    """A rotational inertia `(3, 3)` (earth axes) and a pure moment `(3,)` on one
    frame of a group."""

    frame: int = eqx.field(static=True)
    inertia: Array
    moment: Array


def group_accelerations(frames, dofs, parents, pins, sets, rots, eps=1e-12):
    """Solve a group's equations of motion (module docstring).

    **Arguments:** `frames`: the group's `Frame`s (first the root), whose
    `acceleration` and `alpha` are used where not free; `dofs`: per frame,
    `(translation slice or None, rotation slice or None)` into the generalised
    accelerations; `parents`: per frame, the index of the frame its origin is
    pinned to (None: its own); `pins`: per frame, the pin's offset from the
    parent's origin (earth axes, `(3,)` or None); `sets`, `rots`: `PointSet`s and
    `Rotational`s. A tiny multiple `eps` of the mass matrix's diagonal keeps a
    direction without inertia (two point masses on a massless body) at zero
    acceleration.

    **Returns:** the generalised accelerations and, per frame, its translational
    and angular acceleration.
    """
    n = max(s.stop for d in dofs for s in d if s is not None)

    def accelerate(u):
        acc, alp = [], []
        for f, (tr, rt) in enumerate(dofs):
            fr = frames[f]
            alpha = u[rt] if rt is not None else fr.alpha
            if tr is not None:
                a = u[tr]
            elif parents[f] is not None:
                p = parents[f]
                w = frames[p].omega
                rho = pins[f]
                a = acc[p] + jnp.cross(alp[p], rho) + jnp.cross(w, jnp.cross(w, rho))
            else:
                a = fr.acceleration
            acc.append(a)
            alp.append(alpha)
        points = []
        for s in sets:
            fr = frames[s.frame]
            rho = s.positions - fr.position
            w = fr.omega
            points.append(
                acc[s.frame]
                + jnp.cross(alp[s.frame], rho)
                + jnp.cross(w, jnp.cross(w, rho))
            )
        return points, [alp[r.frame] for r in rots], acc, alp

    zero = jnp.zeros(n)
    c_pts, c_rot = accelerate(zero)[:2]
    jac = jax.jacfwd(lambda u: accelerate(u)[:2])(zero)
    M = jnp.zeros((n, n))
    F = jnp.zeros(n)
    for s, c, J in zip(sets, c_pts, jac[0]):
        # J: (K, 3, n)
        MJ = jnp.einsum("kij,kjn->kin", s.masses, J)
        M = M + jnp.einsum("kim,kin->mn", J, MJ)
        f = s.forces - jnp.einsum("kij,kj->ki", s.masses, c)
        F = F + jnp.einsum("kin,ki->n", J, f)
    for r, c, J in zip(rots, c_rot, jac[1]):
        w = frames[r.frame].omega
        M = M + J.T @ r.inertia @ J
        tau = r.moment - jnp.cross(w, r.inertia @ w) - r.inertia @ c
        F = F + J.T @ tau
    M = M + eps * jnp.diag(jnp.diag(M))
    u = pivoted_solve(M[None], F[None, :, None])[0, :, 0]  # no LAPACK call
    _, _, acc, alp = accelerate(u)
    return u, acc, alp
