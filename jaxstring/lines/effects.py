"""Seabed contact of mooring lines, MoorDyn's law with smooth edges.

The other loads on a mooring network -- weight, buoyancy, Morison drag in a
current -- are the chain core's (`jaxstring.chain`); added mass is part of the
model's mass matrix (line-type Ca, CaAx and point Ca), not an effect.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._arrays import FloatScalar, f64 as _f64
from .._validate import check_nonnegative, check_shape
from ..chain import AbstractChainLoad, ChainForces


class Seabed(AbstractChainLoad):
    """A flat seabed at z = -`depth`: MoorDyn's contact law with smooth edges.

    A line node at penetration delta = -depth - z > 0 gets the vertical force
    F_z = (kBot delta - cBot v_z) d l_i (kBot in Pa/m, cBot in Pa s/m, per unit of
    the node's projected area d l_i), and a friction force against its horizontal
    velocity v_h that grows linearly, mu FricDamp |v_h|, and saturates at
    mu |F_z| (MoorDyn's FricDamp = 200 N s/m, StatDynFricScale = 1). Here both
    edges are smooth, so that implicit solvers and gradients see no kink:

    - contact: delta+ = eps log(1 + exp(delta / eps)) (a softplus of width
      `eps`), and the damping is switched on by the logistic step
      1 / (1 + exp(-delta / eps)), as on rods: both tails are exponential, so a
      node a few eps above the seabed feels none of it (an algebraic edge such
      as (delta + sqrt(delta^2 + eps^2)) / 2 would leave kBot eps^2 / (4 |delta|)
      per unit area on every node above the seabed, 1e-3 N on a 1 m segment of
      a 2 cm line 12 m up at MoorDyn's kBot of 3e6 Pa/m);
    - friction: F_h = -mu FricDamp |F_z| v_h / sqrt(F_z^2 + (FricDamp |v_h|)^2),
      equal to MoorDyn's law in both limits (slow: -mu FricDamp v_h; fast:
      mu |F_z| against v_h) and smooth through v_h = 0.

    **Arguments:**

    - `depth`: water depth, m (> 0; the seabed is the plane z = -depth).
    - `kBot`: seabed stiffness per area, Pa/m (MoorDyn's default 3e6).
    - `cBot`: seabed damping per area, Pa s/m (default 3e5).
    - `friction`: friction coefficient mu (MoorDyn's FrictionCoefficient, default 0).
    - `fric_damp`: slope of the friction at low speed per mu, N s/m (default 200).
    - `eps`: width of the smooth contact edge, m (default 1e-3).
    """

    depth: FloatScalar = eqx.field(converter=_f64)
    kBot: FloatScalar = eqx.field(converter=_f64, default=3.0e6)
    cBot: FloatScalar = eqx.field(converter=_f64, default=3.0e5)
    friction: FloatScalar = eqx.field(converter=_f64, default=0.0)
    fric_damp: FloatScalar = eqx.field(converter=_f64, default=200.0)
    eps: FloatScalar = eqx.field(converter=_f64, default=1e-3)

    def __check_init__(self):
        for name, unit in (
            ("depth", "m"),
            ("kBot", "Pa/m"),
            ("cBot", "Pa s/m"),
            ("friction", ""),
            ("fric_damp", "N s/m"),
            ("eps", "m"),
        ):
            check_shape(name, getattr(self, name), (), unit)
            check_nonnegative(name, getattr(self, name), unit)

    def forces(self, t, kin, env):
        del t, env
        delta = (-self.depth - kin.positions[:, 2]) / self.eps
        pen = self.eps * jax.nn.softplus(delta)
        on = jax.nn.sigmoid(delta)
        area = kin.diameter * kin.length
        vz = kin.velocities[:, 2]
        fz = (self.kBot * pen - self.cBot * vz * on) * area
        vh = kin.velocities[:, :2]
        speed2 = jnp.sum(vh * vh, axis=-1)
        c = self.fric_damp
        den = jnp.sqrt(fz**2 + c**2 * speed2 + (1e-12 * c) ** 2)
        fh = -(self.friction * c * jnp.abs(fz) / den)[:, None] * vh
        nodes = jnp.concatenate([fh, fz[:, None]], axis=1)
        return ChainForces(nodes=nodes, points=jnp.zeros_like(kin.point_positions))
