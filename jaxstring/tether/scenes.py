"""Named tether scenes reproducing Blintsov (2017), section 5 and Table 1.

* ``tether_fixed``: fixed released length (section 5.1, Fig 5).
* ``tether_winch``: the same motion with haul-in during the rise and pay-out during the
  forward motion (Fig 6).

Table 1: L = 100 m, N = 101, rho = 1024 kg/m^3, d = 10 mm, c_n = 1, c_t = 0.1, c_l = 0;
T = 0.1 s, T1 = 0.025 s, k = 10000 N. Neutral buoyancy (F_g = -F_b), uniform current
v_c = (-1, 0, 0) m/s; x north, z up. Root fixed at the origin; running end at
(0, 0, -50) m at t0 = 0; 0-10 s still; 10-35 s rising at 1 m/s; 35-45 s still; 45-70 s
moving forward (+x) at 1 m/s. Integrated with Dormand-Prince ("dopri5").

Choices the paper leaves open (stated here so that they can be changed):

- initial shape: an arc of the full length through both mounts, bulging downstream
  (-x), at rest; the line settles during the first 10 s as in the paper;
- added mass coefficient C_a = 1 (a circular cylinder moving normal to its axis);
- end-link law F = k (l - g)/L_link with L_link = L/(N + 1) (the paper's
  proportional law; it also holds for a zero target length on the drum);
- haul-in speed during the rise: 0.5 m/s (not given in the paper; with the stated
  0.5 m/s pay-out the released length returns to the full 100 m at t = 70 s);
- drag areas: the paper gives "characteristic areas D_t, D_n, D_l which depend on the
  element length and the diameter" without formulas. Here all three are the
  projected area d l_e (`tangential_area="projected"`), so that c_t = 0.1 and
  c_n = 1 of Table 1 refer to the same area. The alternative, tangential drag on
  the wetted surface pi d l_e (`"wetted"`), makes the tangential force pi times
  larger and contradicts the paper's own result: the paper attributes its length
  error entirely to the two proportional end links, whose stretch is
  |F| L_link/k, so its 0.03 % bound (k = 10000 N, L_link = 100/102 m) means
  |F_root| + |F_fast| <= 0.0003 L_r k/L_link = 306 N at all times. With the wetted
  area the exact constraint tensions (no regulator involved) reach 83 + 399 N at
  t = 70 s, while the running end is towed against the current (4.7e-4 from two
  proportional end links alone); with the projected area they stay below 296 N;
- winch law: the reference model of the paper applied to the tracking error e = l - g,
  e'' = -(e/T + e')/T1 (`feedforward=True`, the default of `tether_winch`). It is the
  paper's law wherever the target is constant (every link but the one being paid
  out or hauled in); the law as printed leaves that link lagging by T dg/dt
  (0.05 m at 0.5 m/s, 5.7e-4 of L_r on its own) and is kept as `feedforward=False`.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .._environment import Environment, G, UniformCurrent
from .._scene import Scene
from .._validate import check_choice, check_int, check_nonnegative, check_positive
from ..chain import Buoyancy, Drag, FixedEnd, Gravity, PiecewiseLinear, PrescribedEnd
from .models import TETHER_METHODS, arc_state


TANGENTIAL_AREAS = ("projected", "wetted")


# The paper's water density (Table 1), kg/m^3.
RHO_TABLE1 = 1024.0
PAPER_TIMES = (0.0, 10.0, 35.0, 45.0, 70.0)
PAPER_FAST_PATH = (
    (0.0, 0.0, -50.0),
    (0.0, 0.0, -50.0),
    (0.0, 0.0, -25.0),
    (0.0, 0.0, -25.0),
    (25.0, 0.0, -25.0),
)


def _check_common(N, L, d, rho, t1):
    check_int("N", N, 2)
    check_positive("L", L, "m")
    check_positive("d", d, "m")
    check_positive("rho", rho, "kg/m^3")
    check_positive("t1", t1, "s")


def tether_fixed(
    method: str = "aceam",
    N: int = 101,
    L: float = 100.0,
    d: float = 0.01,
    rho: float = RHO_TABLE1,
    c_n: float = 1.0,
    c_t: float = 0.1,
    c_l: float = 0.0,
    T: float = 0.1,
    T1: float = 0.025,
    k: float = 1e4,
    current=(-1.0, 0.0, 0.0),
    g: float = G,
    added_mass: float = 1.0,
    t1: float = 70.0,
    times=PAPER_TIMES,
    fast_path=PAPER_FAST_PATH,
    smoothing: float = 0.0,
    k_lms=None,
    c_lms: float = 0.0,
    omega: float = 20.0,
    end_links: str = "rigid",
    feedforward: bool = False,
    released=None,
    tangential_area: str = "projected",
    name: str = "tether-fixed",
) -> Scene:
    """The paper's tether at a fixed released length (section 5.1, Fig 5).

    **Arguments:**

    - `method`: link tensions from `"aceam"` (the paper's regulator), `"exact"`
      (constraint tensions) or `"lms"` (springs, k_lms = 40 k unless given).
    - `N` (elements, >= 2), `L` (m), `d` (m), `rho` (kg/m^3): Table 1.
    - `c_n`, `c_t`, `c_l`: drag coefficients. `current`: uniform water velocity, m/s.
    - `T`, `T1` (s), `k` (N): ACEAM regulator and end-link stiffness (Table 1).
    - `g`: m/s^2. `added_mass`: coefficient C_a. `t1`: end time, s.
    - `times` (s, strictly increasing), `fast_path` (m, one (x, y, z) per time): the
      running-end schedule, piecewise linear; `smoothing` (s) ramps its velocity.
    - `k_lms` (N), `c_lms` (N s): LMS springs. `omega` (1/s), `end_links`: exact.
    - `feedforward`: ACEAM reference model with the target's rates.
    - `released`: released length at `times`, m (None: fixed at `L`).
    - `tangential_area`: reference area D_t of `c_t`, `"projected"` (d l_e, the
      area of `c_n`; default, see the module docstring) or `"wetted"` (pi d l_e).
    """
    _check_common(N, L, d, rho, t1)
    check_nonnegative("added_mass", added_mass)
    check_choice("tangential_area", tangential_area, TANGENTIAL_AREAS)
    fast = PrescribedEnd(times, fast_path, smoothing=smoothing)
    schedule = None
    if released is not None:
        schedule = PiecewiseLinear(times, released, smoothing=smoothing)
    check_choice("method", method, tuple(TETHER_METHODS))
    if method == "aceam":
        link_options = dict(T=T, T1=T1, k=k, feedforward=feedforward)
    elif method == "exact":
        link_options = dict(omega=omega, k=k, end_links=end_links)
    else:
        if k_lms is not None:
            check_positive("k_lms", k_lms, "N")
        link_options = dict(k=40.0 * k if k_lms is None else k_lms, c=c_lms)
    model = TETHER_METHODS[method](
        L=L,
        d=d,
        mass_per_length=rho * np.pi * d**2 / 4,  # neutral buoyancy
        added_mass=added_mass,
        N=N,
        root=FixedEnd(np.zeros(3)),
        fast=fast,
        released=schedule,
        **link_options,
    )
    c_t_drag = c_t / np.pi if tangential_area == "projected" else c_t
    effects = (
        Gravity(),
        Buoyancy(),
        # `Drag` takes the axial coefficient on pi d l_e; c_t on d l_e is c_t/pi
        # on pi d l_e.
        Drag(Cd=c_n, CdAx=c_t_drag, Cl=c_l if c_l else None),
    )
    env = Environment(g=g, rho_water=rho, current=UniformCurrent(current))
    y0 = arc_state(model, bulge=(-1.0, 0.0, 0.0), t0=float(np.asarray(times)[0]))
    return Scene(
        model=model, effects=effects, y0=y0, t1=t1, name=f"{name}/{method}", env=env
    )


def tether_winch(
    method: str = "aceam",
    haul_speed: float = 0.5,
    payout_speed: float = 0.5,
    times=PAPER_TIMES,
    released=None,
    feedforward: bool = True,
    **kw,
) -> Scene:
    """The paper's tether with pay-out and haul-in (section 4.5, Fig 6).

    The released length is L (0-10 s), hauled in at `haul_speed` m/s while the
    running end rises (10-35 s), held (35-45 s) and paid out at `payout_speed` m/s
    during the forward motion (45-70 s); or any `released` schedule at `times` (m).
    `feedforward`: ACEAM reference model on the tracking error (default; False: the
    law as printed, which lags a paying-out link by T dg/dt). Other arguments as
    `tether_fixed`.
    """
    check_nonnegative("haul_speed", haul_speed, "m/s")
    check_nonnegative("payout_speed", payout_speed, "m/s")
    if released is None:
        L = kw.get("L", 100.0)
        t = np.asarray(times, float)
        if t.shape != (5,):
            raise ValueError(
                "`times` must have the paper's 5 knots when `released` is not given; "
                f"got {times!r}."
            )
        # The released length must stay within [2 link lengths, L] (the running
        # end is attached: N + 1 links).
        N = kw.get("N", 101)
        check_int("N", N, 2)
        check_positive("L", L, "m")
        if np.all(np.diff(t) > 0):  # else PrescribedEnd refuses `times`
            haul_max = (L - 2 * L / (N + 1)) / (t[2] - t[1])
            if haul_speed > haul_max:
                raise ValueError(
                    f"`haul_speed` must be <= {haul_max:g} m/s (hauling in for "
                    f"{t[2] - t[1]:g} s leaves 2 links of L = {L:g} m); got "
                    f"{haul_speed!r}."
                )
            payout_max = haul_speed * (t[2] - t[1]) / (t[4] - t[3])
            if payout_speed > payout_max * (1 + 1e-12):
                raise ValueError(
                    f"`payout_speed` must be <= {payout_max:g} m/s (paying out for "
                    f"{t[4] - t[3]:g} s after hauling in "
                    f"{haul_speed * (t[2] - t[1]):g} m returns to L = {L:g} m); got "
                    f"{payout_speed!r}."
                )
        hauled = L - haul_speed * (t[2] - t[1])
        released = (L, L, hauled, hauled, hauled + payout_speed * (t[4] - t[3]))
    return tether_fixed(
        method=method,
        times=times,
        released=released,
        feedforward=feedforward,
        name="tether-winch",
        **kw,
    )


def tether_fold(
    method: str = "exact",
    interior_deg: float = 110.0,
    N: int = 11,
    L: float = 10.0,
    d: float = 0.01,
    mass_per_length: float = 0.5,
    rho: float = RHO_TABLE1,
    t1: float = 1.0,
    **model_options,
) -> Scene:
    """A sharp bend: a heavy cable folded into a V of interior angle `interior_deg`
    (deg) at its middle node, both ends fixed, released from rest in still water
    (weight, buoyancy, drag).

    The links of an N-node chain (N + 1 links of L/(N + 1)) point down-and-along the
    first half and up-and-along the second; `model_options` go to the tether model
    (e.g. `end_links="spring"` for the exact chain). ACEAM's one-axis projection
    per element fails at link angles of about 90-110 deg (the paper's stated
    weakness), which this scene shows.
    """
    check_choice("method", method, tuple(TETHER_METHODS))
    _check_common(N, L, d, rho, t1)
    check_positive("mass_per_length", mass_per_length, "kg/m")
    if not 0.0 < float(interior_deg) < 180.0:
        raise ValueError(
            f"`interior_deg` must be in (0, 180) deg; got {interior_deg!r}."
        )
    n_links = N + 1
    half = np.radians(interior_deg) / 2
    left = np.array([np.sin(half), 0.0, -np.cos(half)])
    right = np.array([np.sin(half), 0.0, np.cos(half)])
    k = n_links // 2
    pts = np.cumsum(np.array([left] * k + [right] * (n_links - k)) * L / n_links, 0)
    model = TETHER_METHODS[method](
        L=L,
        d=d,
        mass_per_length=mass_per_length,
        N=N,
        root=FixedEnd(np.zeros(3)),
        fast=FixedEnd(jnp.asarray(pts[-1])),
        **model_options,
    )
    y0 = jax.device_put(np.concatenate([pts[:N], np.zeros((N, 3))], axis=1))
    return Scene(
        model=model,
        effects=(Gravity(), Buoyancy(), Drag(Cd=1.0, CdAx=0.1)),
        y0=y0,
        t1=t1,
        name="tether-fold",
        env=Environment(rho_water=rho),
    )
