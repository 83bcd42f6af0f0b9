r"""Rigid bodies of a mooring system (MoorDyn's BODIES), and rotations in pure JAX.

A `Body` holds what a MoorDyn v2 BODIES row gives: how it moves (`kind`), the pose
of its reference point, its mass, centre of gravity, principal inertia, displaced
volume and hydrodynamic coefficients. Every parameter is a float64 array leaf, so
that `jax.grad`, `jax.jacfwd` and `jax.vmap` see it.

Orientation follows MoorDyn (`Euler2Quat`, MoorDyn v2.7 Misc.hpp): three angles
$(\phi, \theta, \psi)$ (roll, pitch, yaw, rad) give the body-to-global rotation

$$R = R_x(\phi)\,R_y(\theta)\,R_z(\psi),$$

rotations about the body's own axes taken in the order x, y, z (intrinsic X-Y-Z;
scipy's `Rotation.from_euler("XYZ", angles)`); `euler_angles` is its inverse with
the middle angle in $[-\pi/2, \pi/2]$ (MoorDyn's `Quat2Euler`). To first order in
small angles $R \approx I + S(\phi, \theta, \psi)$, so small roll, pitch and yaw
are small rotations about the global x, y and z axes. MoorPy's `rotationMatrix`
takes the other order ($R_z R_y R_x$); the two agree to first order.

Quaternions are scalar-first, $q = (w, x, y, z)$, unit, with $w \ge 0$ where a
sign is chosen (`matrix_to_quat`); MoorDyn keeps Eigen's $(x, y, z, w)$ in its
state. `skew(a)` is the matrix with `skew(a) @ b = cross(a, b)` (MoorDyn's
`getH(a)` is `-skew(a)`).
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._arrays import FloatScalar, f64, param as _param
from .._validate import (
    check_choice,
    check_nonnegative,
    check_shape_finite,
    is_concrete,
)


__all__ = [
    "Body",
    "BODY_KINDS",
    "skew",
    "rotation_matrix",
    "euler_angles",
    "rotation_from_vector",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_multiply",
]

# MoorDyn's body attachments: FIXED (held at its deck pose), FREE (6 DOF),
# COUPLED (pose given by the caller, 6 DOF driven) and CPLDPIN (position given,
# rotation free), here "pinned".
BODY_KINDS = ("fixed", "free", "coupled", "pinned")


def _vector(n):
    """A converter to a float64 array that broadcasts a scalar to shape (n,)."""

    def convert(x):
        x = f64(x)
        return jnp.broadcast_to(x, (n,)) if x.ndim == 0 else x

    return convert


class Body(eqx.Module):
    r"""A rigid body of a mooring system (one row of MoorDyn's BODIES section).

    **Arguments:**

    - `kind`: how the body moves (static): `"fixed"` (held at its pose),
      `"free"` (6 degrees of freedom), `"coupled"` (its pose is given by the caller:
      a vessel) or `"pinned"` (its reference point is given, its rotation is free:
      MoorDyn's CoupledPinned).
    - `position`: the reference point, global, m, shape (3,).
    - `rotation`: roll, pitch, yaw, rad, shape (3,): the body-to-global rotation
      $R = R_x R_y R_z$ (module docstring; MoorDyn's deck gives degrees).
    - `mass`: kg, $\ge 0$.
    - `cg`: centre of gravity in the body frame, relative to the reference point,
      m, shape (3,).
    - `inertia`: principal moments of inertia about the centre of gravity, body
      axes, kg m^2, shape (3,), $\ge 0$.
    - `volume`: displaced volume, m^3, $\ge 0$ (buoyancy $\rho_w g V$; added mass
      $\rho_w V C_a$).
    - `CdA`: drag coefficient times area, shape (6,), $\ge 0$: translational (m^2)
      then rotational (m^5), body axes.
    - `Ca`: translational added-mass coefficients on $\rho_w V$, body axes,
      shape (3,), $\ge 0$.
    - `name`: a label for messages (static), e.g. `"body 1"`.

    Scalars broadcast: `inertia=1e9` means `(1e9, 1e9, 1e9)`, `CdA=0.1` all six.

    **Raises:** `ValueError` naming the field, its value and the valid range; a
    free body with zero mass and zero volume (no load could hold it still, and no
    inertia could move it) is refused, named.
    """

    kind: str = eqx.field(static=True)
    position: Float[Array, "3"] = _param()
    rotation: Float[Array, "3"] = _param(default=(0.0, 0.0, 0.0))
    mass: FloatScalar = _param(default=0.0)
    cg: Float[Array, "3"] = _param(default=(0.0, 0.0, 0.0))
    inertia: Float[Array, "3"] = eqx.field(converter=_vector(3), default=0.0)
    volume: FloatScalar = _param(default=0.0)
    CdA: Float[Array, "6"] = eqx.field(converter=_vector(6), default=0.0)
    Ca: Float[Array, "3"] = eqx.field(converter=_vector(3), default=0.0)
    name: str = eqx.field(static=True, default="body")

    def __check_init__(self):
        check_choice("body kind", self.kind, BODY_KINDS)
        who = f" of {self.name}"
        for field, shape, unit in (
            ("position", (3,), "m"),
            ("rotation", (3,), "rad"),
            ("cg", (3,), "m"),
            ("mass", (), "kg"),
            ("volume", (), "m^3"),
            ("inertia", (3,), "kg m^2"),
            ("CdA", (6,), ""),
            ("Ca", (3,), ""),
        ):
            check_shape_finite(field + who, getattr(self, field), shape, unit)
        for field, unit in (
            ("mass", "kg"),
            ("volume", "m^3"),
            ("inertia", "kg m^2"),
            ("CdA", ""),
            ("Ca", ""),
        ):
            check_nonnegative(f"{field}{who}", getattr(self, field), unit)
        if (
            self.kind == "free"
            and is_concrete(self.mass)
            and is_concrete(self.volume)
            and float(self.mass) == 0.0
            and float(self.volume) == 0.0
        ):
            raise ValueError(
                f"{self.name} is free with `mass` = 0 kg and `volume` = 0 m^3: a free "
                "body needs mass > 0 or volume > 0 (make it 'fixed', 'coupled' or "
                "'pinned', or give it a mass)."
            )

    @property
    def matrix(self) -> Float[Array, "3 3"]:
        """The body-to-global rotation matrix of `rotation`."""
        return rotation_matrix(self.rotation)


# ---------------------------------------------------------------------------
# Rotations


def skew(a) -> Float[Array, "3 3"]:
    """The cross-product matrix of `a` (shape (3,)): `skew(a) @ b = cross(a, b)`."""
    a = jnp.asarray(a)
    z = jnp.zeros_like(a[0])
    return jnp.stack(
        [
            jnp.stack([z, -a[2], a[1]]),
            jnp.stack([a[2], z, -a[0]]),
            jnp.stack([-a[1], a[0], z]),
        ]
    )


def _rx(a):
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack(
        [jnp.stack([o, z, z]), jnp.stack([z, c, -s]), jnp.stack([z, s, c])]
    )


def _ry(a):
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack(
        [jnp.stack([c, z, s]), jnp.stack([z, o, z]), jnp.stack([-s, z, c])]
    )


def _rz(a):
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(a), jnp.zeros_like(a)
    return jnp.stack(
        [jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])]
    )


def rotation_matrix(angles) -> Float[Array, "3 3"]:
    r"""Build the body-to-global rotation of roll, pitch, yaw (MoorDyn's convention).

    **Arguments:** `angles`: $(\phi, \theta, \psi)$, rad, shape (3,).

    **Returns:** $R = R_x(\phi) R_y(\theta) R_z(\psi)$, shape (3, 3).
    """
    a = jnp.asarray(angles)
    return _rx(a[0]) @ _ry(a[1]) @ _rz(a[2])


def euler_angles(R) -> Float[Array, "3"]:
    r"""Recover roll, pitch, yaw from a rotation matrix (inverse of `rotation_matrix`).

    The middle angle lies in $[-\pi/2, \pi/2]$ (MoorDyn's `Quat2Euler`). At
    $\theta = \pm\pi/2$ (gimbal lock) roll and yaw are not separable and the
    derivative is not defined.

    **Arguments:** `R`: a rotation matrix, shape (3, 3).

    **Returns:** $(\phi, \theta, \psi)$, rad, shape (3,).
    """
    R = jnp.asarray(R)
    # R[0, 2] = sin(theta); R[0, 0], R[0, 1] = cos(theta) (cos psi, -sin psi);
    # R[1, 2], R[2, 2] = cos(theta) (-sin phi, cos phi)
    c = jnp.sqrt(R[0, 0] ** 2 + R[0, 1] ** 2)
    theta = jnp.arctan2(R[0, 2], c)
    psi = jnp.arctan2(-R[0, 1], R[0, 0])
    phi = jnp.arctan2(-R[1, 2], R[2, 2])
    return jnp.stack([phi, theta, psi])


def rotation_from_vector(v) -> Float[Array, "3 3"]:
    r"""Build the rotation by angle $|v|$ about the axis $v/|v|$ (Rodrigues).

    $R = I + \frac{\sin\alpha}{\alpha} S + \frac{1 - \cos\alpha}{\alpha^2} S^2$,
    $S$ = `skew(v)`, $\alpha = |v|$, with the series of both coefficients near
    $\alpha = 0$, so that values and derivatives are exact there
    ($\partial R/\partial v_i = S(e_i)$ at $v = 0$).

    **Arguments:** `v`: rotation vector, rad, shape (3,).

    **Returns:** the rotation matrix, shape (3, 3).
    """
    v = jnp.asarray(v)
    a2 = jnp.sum(v * v)
    small = a2 < 1e-8
    a2s = jnp.where(small, 1.0, a2)
    a = jnp.sqrt(a2s)
    # sin(a)/a = 1 - a^2/6 + a^4/120; (1 - cos a)/a^2 = 1/2 - a^2/24 + a^4/720
    s1 = jnp.where(small, 1.0 - a2 / 6.0 + a2 * a2 / 120.0, jnp.sin(a) / a)
    s2 = jnp.where(small, 0.5 - a2 / 24.0 + a2 * a2 / 720.0, (1.0 - jnp.cos(a)) / a2s)
    S = skew(v)
    return jnp.eye(3, dtype=v.dtype) + s1 * S + s2 * (S @ S)


def quat_to_matrix(q) -> Float[Array, "3 3"]:
    """Build the rotation matrix of a quaternion.

    **Arguments:** `q`: $(w, x, y, z)$, shape (4,); normalised here (MoorDyn
    normalises at every use too), so any non-zero quaternion is accepted.

    **Returns:** the rotation matrix, shape (3, 3).
    """
    q = jnp.asarray(q)
    q = q / jnp.sqrt(jnp.sum(q * q))
    w, x, y, z = q[0], q[1], q[2], q[3]
    return jnp.stack(
        [
            jnp.stack(
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)]
            ),
            jnp.stack(
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)]
            ),
            jnp.stack(
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]
            ),
        ]
    )


def matrix_to_quat(R) -> Float[Array, "4"]:
    """Recover the unit quaternion of a rotation matrix (inverse of `quat_to_matrix`).

    Shepperd's method: the largest of $4w^2, 4x^2, 4y^2, 4z^2$ (read from the
    trace and the diagonal) is taken as the pivot, so that no digits cancel at any
    rotation; branch-free (`jnp.where`), so it traces once and batches under
    `jax.vmap`.

    **Arguments:** `R`: a rotation matrix, shape (3, 3).

    **Returns:** $(w, x, y, z)$, shape (4,), unit, with $w \\ge 0$.
    """
    R = jnp.asarray(R)
    t = R[0, 0] + R[1, 1] + R[2, 2]
    # 4 w^2, 4 x^2, 4 y^2, 4 z^2 (each 1 + a signed sum of the diagonal)
    d = jnp.stack(
        [
            1.0 + t,
            1.0 + R[0, 0] - R[1, 1] - R[2, 2],
            1.0 - R[0, 0] + R[1, 1] - R[2, 2],
            1.0 - R[0, 0] - R[1, 1] + R[2, 2],
        ]
    )
    k = jnp.argmax(d)
    s = 2.0 * jnp.sqrt(jnp.maximum(d[k], 1e-300))  # 4 |pivot component|
    a = R[2, 1] - R[1, 2]  # 4 w x
    b = R[0, 2] - R[2, 0]  # 4 w y
    c = R[1, 0] - R[0, 1]  # 4 w z
    e = R[0, 1] + R[1, 0]  # 4 x y
    f = R[0, 2] + R[2, 0]  # 4 x z
    g = R[1, 2] + R[2, 1]  # 4 y z
    cands = jnp.stack(
        [
            jnp.stack([0.25 * s, a / s, b / s, c / s]),
            jnp.stack([a / s, 0.25 * s, e / s, f / s]),
            jnp.stack([b / s, e / s, 0.25 * s, g / s]),
            jnp.stack([c / s, f / s, g / s, 0.25 * s]),
        ]
    )
    q = cands[k]
    q = q / jnp.sqrt(jnp.sum(q * q))
    return jnp.where(q[0] < 0, -q, q)


def quat_multiply(p, q) -> Float[Array, "4"]:
    r"""Multiply two quaternions (Hamilton product $p \otimes q$: rotate by $q$,
    then by $p$).

    **Arguments:** `p`, `q`: $(w, x, y, z)$, shape (4,) each.

    **Returns:** $p \otimes q$, shape (4,).
    """
    p, q = jnp.asarray(p), jnp.asarray(q)
    pw, pv = p[0], p[1:]
    qw, qv = q[0], q[1:]
    w = pw * qw - jnp.dot(pv, qv)
    v = pw * qv + qw * pv + jnp.cross(pv, qv)
    return jnp.concatenate([w[None], v])
