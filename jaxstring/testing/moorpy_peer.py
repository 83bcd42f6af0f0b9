"""MoorPy's model of a `jaxstring.lines.MooringSystem`: the independent reference
of the statics' tests and benchmarks (MoorPy, https://github.com/NREL/MoorPy,
BSD 3-Clause; `pip install moorpy`).

`moorpy_system(system, loads)` builds the same bodies, points and lines in a
`moorpy.System` (bodies: MoorPy type 0 free, 1 fixed, -1 coupled; points: 0 free,
1 fixed, -1 coupled, or attached to their body; every line one catenary), with the
system's g, water density and depth, and the loads as MoorPy's external forces.
MoorPy puts a body's buoyancy at its reference point when its metacentre `rM` is
zero, as here; a hydrostatic matrix is handed over only as its heave term
`AWP = K[2, 2]/(rho g)` about z = 0 (MoorPy has no other), so only such systems
compare. Pinned bodies have no MoorPy counterpart.

MoorPy's Euler angles are its own (`rotationMatrix`: z-y-x); poses compare where
the rotations are small, stiffness at zero rotation.
"""

import math

import numpy as np


def moorpy_system(system, loads=None, n_segments: int = 40):
    """A `moorpy.System` of `system` (initialised, not yet at equilibrium).

    **Arguments:** `system`: a `MooringSystem`; `loads`: a `MooringLoads` or
    None; `n_segments`: MoorPy's plotting segments per line (no effect on the
    statics).

    **Returns:** the `moorpy.System`.
    """
    import moorpy

    depth = float(system.depth) if system.depth is not None else 1e6
    ms = moorpy.System(depth=depth, rho=float(system.rho), g=float(system.g))
    kinds = {"free": 0, "fixed": 1, "coupled": -1}
    bl = np.zeros((len(system.bodies), 6)) if loads is None else np.asarray(loads.body)
    pl = np.zeros((len(system.points), 3)) if loads is None else np.asarray(loads.point)
    for i, b in enumerate(system.bodies):
        if b.kind not in kinds:
            raise ValueError(f"MoorPy has no {b.kind!r} body ({b.name}).")
        AWP = 0.0
        if system.hydrostatics is not None:
            K = np.asarray(system.hydrostatics[i])
            rest = K.copy()
            rest[2, 2] = 0.0
            z0 = float(system.hydrostatic_pose[i][2])
            if np.any(rest != 0) or z0 != 0:
                raise ValueError(
                    "MoorPy takes a hydrostatic heave stiffness about z = 0 only."
                )
            AWP = K[2, 2] / (float(system.rho) * float(system.g))
        ms.addBody(
            kinds[b.kind],
            np.concatenate([np.asarray(b.position), np.asarray(b.rotation)]),
            m=float(b.mass),
            v=float(b.volume),
            rCG=np.asarray(b.cg),
            AWP=AWP,
            f6Ext=bl[i],
        )
    for k, p in enumerate(system.points):
        pos = np.asarray(p.position, float)
        if p.kind == "body":
            ms.addPoint(1, pos, m=float(p.mass), v=float(p.volume), body=p.body + 1)
            ms.pointList[-1].fExt = pl[k]
        else:
            ms.addPoint(kinds[p.kind], pos, m=float(p.mass), v=float(p.volume),
                        fExt=pl[k])  # fmt: skip
    for j, (a, b) in enumerate(system.attach):
        d = float(system.d[j])
        w = float(system.w[j])
        lt = ms.setLineType(
            name=f"type{j}",
            d_vol=d,
            mass=w,
            EA=float(system.EA[j]),
            dnommm=1000.0 * d,
            w=(w - float(system.rho) * math.pi / 4 * d * d) * float(system.g),
        )
        ms.addLine(float(system.L[j]), lt, nSegs=n_segments, pointA=a + 1,
                   pointB=b + 1, cb=float(system.CB[j]))  # fmt: skip
    ms.initialize()
    return ms


def moorpy_tensions(ms):
    """(n_lines, 2) tension magnitudes at end A and end B of a MoorPy system, N."""
    return np.array(
        [[np.linalg.norm(ln.fA), np.linalg.norm(ln.fB)] for ln in ms.lineList]
    )
