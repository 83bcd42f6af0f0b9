"""Bad input anywhere in the API raises a ValueError that names the argument, the
value it got and the valid range, before anything compiles; the command line exits
with code 2 and that message, without a traceback.

Every case runs with `diffrax.diffeqsolve` and jaxstring's own step loop replaced by a
function that fails the test: a refusal that came only after a solve had been traced
(and compiled) does not count. (tests/test_errors.py holds further cases of the string
pendulum and of `simulate`; none is repeated here.)
"""

import functools

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import tandem as td, tether as tt
from jaxstring._solvers import loop as solver_loop
from jaxstring.cli.main import main


NAN = float("nan")


@pytest.fixture(autouse=True)
def no_solve(monkeypatch):
    def traced(*args, **kwargs):
        raise AssertionError("a solve was traced before the input was refused")

    monkeypatch.setattr(diffrax, "diffeqsolve", traced)
    monkeypatch.setattr(solver_loop, "solve", traced)  # jaxstring's own step loop


# Scenes the cases start from (built once per process, on first use).


@functools.cache
def pendulum():
    return js.string_pendulum(k=4, t1=0.5)


@functools.cache
def tether():
    model = tt.AceamTether(L=10.0, d=0.01, mass_per_length=1.0, N=4)
    return js.Scene(model=model, effects=(), y0=jnp.zeros((4, 6)), t1=1.0)


@functools.cache
def fpso():
    model = td.MooredFPSO(fpso=td.fpso_hull(), x_t=128.0)
    return js.Scene(model=model, effects=(), y0=jnp.zeros(6), t1=1.0)


def string(**kw):
    args = dict(l=1.0, mu=1.0, m_s=1.0, EA=1e3, k=4)
    args.update(kw)
    return js.DisplacementString(**args)


def scene(**kw):
    base = pendulum()
    args = dict(model=base.model, effects=base.effects, y0=base.y0, t1=0.5)
    args.update(kw)
    return js.Scene(**args)


def loss(traj, scene):
    del scene
    return jnp.sum(traj.ys**2)


def residuals(traj, scene):
    del scene
    return traj.ys[:, 0, 0]


TS_DOWN = np.array([0.0, 0.3, 0.2])
TS_OUT = np.array([0.0, 0.4, 0.9])

# (id, call, substrings of the message: the argument, the value, the valid range)
CASES = [
    # -- models and effects
    ("string-mu-array", lambda: string(mu=np.ones(3)), ["`mu`", "(3,)", "scalar"]),
    ("string-l-nan", lambda: string(l=NAN), ["`l`", "nan", "> 0"]),
    ("string-k-bool", lambda: string(k=True), ["`k`", "True", "integer >= 2"]),
    ("string-dim-1", lambda: string(dim=1), ["`dim`", "1", "2 or 3"]),
    ("kelvin-voigt-nan", lambda: js.KelvinVoigt(alpha=NAN), ["`alpha`", "nan", ">= 0"]),
    ("env-rho-0", lambda: js.Environment(rho_water=0.0), ["`rho_water`", "0.0", "> 0"]),
    (
        "current-shape",
        lambda: js.UniformCurrent(jnp.zeros(2)),
        ["`velocity`", "(2,)", "(3,)"],
    ),
    (
        "aceam-N-1",
        lambda: tt.AceamTether(L=10.0, d=0.01, mass_per_length=1.0, N=1),
        ["`N`", "1", "integer >= 2"],
    ),
    (
        "aceam-L-array",
        lambda: tt.AceamTether(L=np.ones(2), d=0.01, mass_per_length=1.0, N=4),
        ["`L`", "(2,)", "scalar"],
    ),
    (
        "lms-c-negative",
        lambda: tt.LmsTether(L=10.0, d=0.01, mass_per_length=1.0, N=4, c=-1.0),
        ["`c`", "-1.0", ">= 0"],
    ),
    (
        "exact-end-links",
        lambda: tt.ExactTether(
            L=10.0, d=0.01, mass_per_length=1.0, N=4, end_links="soft"
        ),
        ["`end_links`", "'soft'", "'rigid' or 'spring'"],
    ),
    (
        "prescribed-times",
        lambda: tt.PrescribedEnd([0.0, 1.0, 0.5], np.zeros((3, 3))),
        ["`times`", "0.5", "strictly increasing"],
    ),
    (
        "fixed-end-shape",
        lambda: tt.FixedEnd(jnp.zeros(2)),
        ["`position`", "(2,)", "(3,)"],
    ),
    ("tether-drag", lambda: tt.Drag(Cd=-1.0), ["`Cd`", "-1.0", ">= 0"]),
    ("hull-C_B", lambda: td.fpso_hull(C_B=2.0), ["`C_B`", "2.0", "(0, 1]"]),
    ("hull-L", lambda: td.shuttle_hull(L=0.0), ["`L`", "0.0", "> 0"]),
    ("hawser-k_h", lambda: td.Hawser(k_h=-1.0), ["`k_h`", "-1.0", "> 0"]),
    ("mooring-rho_m", lambda: td.TurretMooring(rho_m=0.0), ["`rho_m`", "0.0", "> 0"]),
    (
        "damping-shape",
        lambda: td.LinearDamping(fpso=(1.0, 1.0)),
        ["`fpso`", "(2,)", "(3,)"],
    ),
    (
        "wind-loading",
        lambda: td.OCIMFWind(loading=("full", "loaded")),
        ["`loading`", "'full'", "'loaded' or 'ballast'"],
    ),
    ("thrust-X_max", lambda: td.ConstantThrust(X_max=0.0), ["`X_max`", "0.0", "> 0"]),
    (
        "tandem-x_t",
        lambda: td.Tandem(fpso=td.fpso_hull(), shuttle=td.shuttle_hull(), x_t=500.0),
        ["`x_t`", "500.0", "<= L/2"],
    ),
    (
        "compensator-gains",
        lambda: td.NonlinearCompensator(K_P=(1.0, 0.1, 0.3)),
        ["`K_P`", "(3,)", "(2,)"],
    ),
    (
        "compensator-omega",
        lambda: td.NonlinearCompensator.from_bandwidth(omega=-0.05),
        ["`omega`", "-0.05", ">= 0"],
    ),
    ("pd-d_ref", lambda: td.ComputedForcePD(d_ref=-1.0), ["`d_ref`", "-1.0", "> 0"]),
    ("hawser-line-N", lambda: td.hawser_line(N=1), ["`N`", "1", "integer >= 2"]),
    (
        "tandem-line-tandem",
        lambda: td.TandemLine("fpso", td.hawser_line()),
        ["`tandem`", "'fpso'", "Tandem"],
    ),
    # -- Scene
    ("scene-t0-nan", lambda: scene(t0=NAN), ["`t0`", "nan", "finite"]),
    ("scene-t1-before-t0", lambda: scene(t0=1.0, t1=0.5), ["`t1`", "0.5", "> t0 = 1"]),
    (
        "scene-t1-array",
        lambda: scene(t1=jnp.array([1.0, 2.0])),
        ["`t1`", "(2,)", "scalar"],
    ),
    ("scene-t1-text", lambda: scene(t1="2"), ["`t1`", "'2'", "number"]),
    (
        "scene-effects-twice",
        lambda: scene(effects=(js.Gravity(), js.Gravity())),
        ["`effects`", "Gravity", "at most once"],
    ),
    (
        "scene-effects-list",
        lambda: scene(effects=[js.Gravity()]),
        ["`effects`", "[Gravity()]", "tuple"],
    ),
    (
        "scene-model",
        lambda: scene(model="string"),
        ["`model`", "'string'", "AbstractModel"],
    ),
    ("scene-y0-text", lambda: scene(y0="rest"), ["`y0`", "'rest'", "floating-point"]),
    ("scene-env", lambda: scene(env=3), ["`env`", "3", "Environment"]),
    # -- scene builders
    (
        "pendulum-mu-nan",
        lambda: js.string_pendulum(mu=NAN),
        ["`mu`", "nan", "> 0"],
    ),
    (
        "pendulum-k-text",
        lambda: js.string_pendulum(k="4"),
        ["`k`", "'4'", "integer >= 2"],
    ),
    (
        "pendulum-effect-typo",
        lambda: js.string_pendulum(effects="gravty"),
        ["effect", "'gravty'", "'gravity'"],
    ),
    (
        "tether-method",
        lambda: js.tether_fixed(method="rk4"),
        ["method", "'rk4'", "'aceam', 'exact', 'lms'"],
    ),
    ("tether-d", lambda: js.tether_fixed(d=-0.01), ["`d`", "-0.01", "> 0"]),
    (
        "tether-k_lms",
        lambda: js.tether_fixed(method="lms", k_lms=-1.0),
        ["`k_lms`", "-1.0", "> 0"],
    ),
    (
        "tether-area",
        lambda: js.tether_fixed(tangential_area="wet"),
        ["tangential_area", "'wet'", "'projected', 'wetted'"],
    ),
    (
        "tether-released",
        lambda: js.tether_fixed(N=6, released=(200.0,) * 5),
        ["`released`", "200", "L = 100"],
    ),
    (
        "tether-current",
        lambda: js.tether_fixed(current=(1.0, 0.0)),
        ["`velocity`", "(2,)", "(3,)"],
    ),
    (
        "winch-haul",
        lambda: js.tether_winch(N=6, haul_speed=10.0),
        ["`haul_speed`", "10.0", "<= 2.85714"],
    ),
    (
        "winch-payout",
        lambda: js.tether_winch(N=6, payout_speed=1.0),
        ["`payout_speed`", "1.0", "<= 0.5"],
    ),
    (
        "winch-times",
        lambda: js.tether_winch(N=6, times=(0.0, 1.0)),
        ["`times`", "(0.0, 1.0)", "5 knots"],
    ),
    (
        "fpso-alone-turret",
        lambda: js.tandem_fpso_alone(x_t_over_L=1.0),
        ["`x_t_over_L`", "1.0", "[-0.5, 0.5]"],
    ),
    (
        "equilibria-wind",
        lambda: js.tandem_equilibria(V_w=-1.0),
        ["`V_w`", "-1.0", ">= 0"],
    ),
    (
        "fishtail-hawser",
        lambda: js.tandem_fishtail(hawser="rope"),
        ["hawser", "'rope'", "'massless', 'line'"],
    ),
    (
        "fishtail-line-option",
        lambda: js.tandem_fishtail(hawser="line", line_options={"NN": 4}),
        ["`line_options`", "'NN'", "'mass_per_length'"],
    ),
    (
        "controlled-law",
        lambda: js.tandem_controlled(law="C"),
        ["law", "'C'", "'A', 'B'"],
    ),
    (
        "controlled-offset",
        lambda: js.tandem_controlled(shuttle_offset_deg=NAN),
        ["`shuttle_offset_deg`", "nan", "finite"],
    ),
    (
        "hopf-F_ast",
        lambda: js.tandem_hopf(F_ast=NAN),
        ["`F_ast`", "nan", "finite"],
    ),
    # -- simulate
    ("simulate-scene", lambda: js.simulate(None), ["`scene`", "NoneType", "Scene"]),
    (
        "simulate-atol-text",
        lambda: js.simulate(pendulum(), atol="1e-6"),
        ["`atol`", "'1e-6'", "> 0"],
    ),
    (
        "simulate-rtol-nan",
        lambda: js.simulate(pendulum(), rtol=NAN),
        ["`rtol`", "nan", "> 0"],
    ),
    (
        "simulate-max_steps-float",
        lambda: js.simulate(pendulum(), max_steps=10.0),
        ["`max_steps`", "10.0", "integer >= 1"],
    ),
    (
        "simulate-n_save",
        lambda: js.simulate(pendulum(), n_save=1),
        ["`n_save`", "1", "integer >= 2"],
    ),
    (
        "simulate-ts-2d",
        lambda: js.simulate(pendulum(), ts=np.zeros((2, 2))),
        ["`ts`", "(2, 2)", "1-d"],
    ),
    (
        "simulate-ts-empty",
        lambda: js.simulate(pendulum(), ts=np.zeros(0)),
        ["`ts`", "[]", "non-empty"],
    ),
    (
        "simulate-ts-nan",
        lambda: js.simulate(pendulum(), ts=np.array([0.0, NAN, 0.3])),
        ["`ts`", "nan", "finite"],
    ),
    (
        "simulate-newton_atol",
        lambda: js.simulate(pendulum(), newton_atol=0.0),
        ["`newton_atol`", "0.0", "> 0"],
    ),
    (
        "simulate-project",
        lambda: js.simulate(pendulum(), project="no"),
        ["`project`", "'no'", "True or False"],
    ),
    (
        "simulate-step_control",
        lambda: js.simulate(pendulum(), step_control="pi"),
        ["step_control", "'pi'", "'newton-limited'"],
    ),
    (
        "simulate-adjoint",
        lambda: js.simulate(pendulum(), adjoint="reverse"),
        ["adjoint", "'reverse'", "'recursive'"],
    ),
    # -- sweep: every member is checked as its constructor would check it
    (
        "sweep-EA-negative",
        lambda: js.sweep(pendulum(), {"EA": [1e3, -1e3, 2e3]}),
        ["`values['EA']`", "member 1", "-1000.0", "> 0"],
    ),
    (
        "sweep-alpha-nan",
        lambda: js.sweep(pendulum(), {"alpha": [0.01, 0.02, NAN]}),
        ["`values['alpha']`", "member 2", "nan", ">= 0"],
    ),
    (
        "sweep-k-fraction",
        lambda: js.sweep(pendulum(), {"k": [4, 2.5]}),
        ["`values['k']`", "member 1", "2.5", "integer >= 2"],
    ),
    (
        "sweep-k-structure",
        lambda: js.sweep(pendulum(), {"k": [4, 8]}),
        ["'k'", "static", "loop over it"],
    ),
    (
        "sweep-grid-l",
        lambda: js.sweep(
            pendulum(), {"EA": [1e3, 2e3], "l": [1.0, 2.0, 0.0]}, grid=True
        ),
        ["`values['l']`", "member 2", "0.0", "> 0"],
    ),
    (
        "sweep-batch-2d",
        lambda: js.sweep(pendulum(), {"EA": [[1e3, 2e3], [3e3, -1.0]]}),
        ["`values['EA']`", "member (1, 1)", "-1.0", "> 0"],
    ),
    (
        "sweep-t1",
        lambda: js.sweep(pendulum(), {"t1": [0.5, -0.5]}),
        ["`values['t1']`", "member 1", "-0.5", "> t0 = 0"],
    ),
    (
        "sweep-g",
        lambda: js.sweep(pendulum(), {"g": [9.81, -9.81]}),
        ["`values['g']`", "member 1", "-9.81", ">= 0"],
    ),
    (
        "sweep-tether-L",
        lambda: js.sweep(tether(), {"L": [100.0, -1.0]}),
        ["`values['L']`", "member 1", "-1.0", "> 0"],
    ),
    (
        "sweep-hull-length",
        lambda: js.sweep(fpso(), {"model.fpso.L": [320.0, 200.0]}),
        ["`values['model.fpso.L']`", "member 1", "200.0", "<= L/2 = 100"],
    ),
    (
        "sweep-text",
        lambda: js.sweep(pendulum(), {"EA": ["stiff"]}),
        ["`values['EA']`", "'stiff'", "numbers"],
    ),
    (
        "sweep-ts",
        lambda: js.sweep(pendulum(), {"EA": [1e3]}, ts=TS_OUT),
        ["`ts`", "0.9", "[0, 0.5]"],
    ),
    (
        "sweep-fn",
        lambda: js.sweep(pendulum(), {"EA": [1e3]}, fn="period"),
        ["`fn`", "'period'", "callable"],
    ),
    (
        "sweep-devices",
        lambda: js.sweep(pendulum(), {"EA": [1e3]}, devices="gpu"),
        ["`devices`", "'gpu'", "'auto', 1, None"],
    ),
    (
        "sweep-twice",
        lambda: js.sweep(pendulum(), {"EA": [1e3], "model.EA": [2e3]}),
        ["`values`", "'EA', 'model.EA'", "once"],
    ),
    (
        "sweep-no-members",
        lambda: js.sweep(pendulum(), {"EA": []}),
        ["`values`", "(0,)", "no members"],
    ),
    # -- fit, value_and_grad, gauss_newton
    (
        "fit-steps",
        lambda: js.fit(pendulum(), loss, ["EA"], steps=0),
        ["`steps`", "0", "integer >= 1"],
    ),
    (
        "fit-learning_rate",
        lambda: js.fit(pendulum(), loss, ["EA"], learning_rate=-0.1),
        ["`learning_rate`", "-0.1", "> 0"],
    ),
    (
        "fit-gtol",
        lambda: js.fit(pendulum(), loss, ["EA"], gtol=-1.0),
        ["`gtol`", "-1.0", ">= 0"],
    ),
    (
        "fit-print_every",
        lambda: js.fit(pendulum(), loss, ["EA"], print_every=-1),
        ["`print_every`", "-1", "integer >= 0"],
    ),
    (
        "fit-optimizer",
        lambda: js.fit(pendulum(), loss, ["EA"], optimizer="adam"),
        ["`optimizer`", "'adam'", "GradientTransformation"],
    ),
    (
        "fit-ts",
        lambda: js.fit(pendulum(), loss, ["EA"], ts=TS_DOWN),
        ["`ts`", "0.2", "increasing"],
    ),
    (
        "fit-checkpoints",
        lambda: js.fit(pendulum(), loss, ["EA"], checkpoints=0),
        ["`checkpoints`", "0", "integer >= 1"],
    ),
    (
        "value_and_grad-ts",
        lambda: js.value_and_grad(pendulum(), loss, ["EA"], ts=TS_OUT),
        ["`ts`", "0.9", "[0, 0.5]"],
    ),
    (
        "value_and_grad-sensitivity-simulate",
        lambda: js.value_and_grad(
            pendulum(), lambda s: 0.0, ["EA"], simulate=False, adjoint="sensitivity"
        ),
        ["`adjoint='sensitivity'`", "simulate=True"],
    ),
    (
        "value_and_grad-sensitivity-projects",
        lambda: js.value_and_grad(
            js.string_pendulum(formulation="natural", k=4, t1=0.5),
            loss,
            ["EA"],
            adjoint="sensitivity",
        ),
        ["`adjoint='sensitivity'`", "NaturalTangentString", "project=False"],
    ),
    (
        "gauss_newton-adjoint",
        lambda: js.gauss_newton(pendulum(), residuals, ["EA"], adjoint="reverse"),
        ["adjoint", "'reverse'", "'sensitivity'"],
    ),
    (
        "gauss_newton-sigma",
        lambda: js.gauss_newton(pendulum(), residuals, ["EA"], sigma=0.0),
        ["`sigma`", "0.0", "> 0"],
    ),
    # -- least_squares
    (
        "least_squares-bounds-pair",
        lambda: js.least_squares(pendulum(), residuals, ["EA"], bounds={"EA": (1.0,)}),
        ["`bounds['EA']`", "[1.]", "pair (low, high)"],
    ),
    (
        "least_squares-bounds-order",
        lambda: js.least_squares(
            pendulum(), residuals, ["EA"], bounds={"EA": (1e7, 1e5)}
        ),
        ["`bounds['EA']`", "(10000000.0, 100000.0)", "low < high"],
    ),
    (
        "least_squares-ts",
        lambda: js.least_squares(pendulum(), residuals, ["EA"], ts=TS_DOWN),
        ["`ts`", "0.2", "increasing"],
    ),
    (
        "least_squares-max_iters",
        lambda: js.least_squares(pendulum(), residuals, ["EA"], max_iters=1.5),
        ["`max_iters`", "1.5", "integer >= 1"],
    ),
    (
        "least_squares-tol",
        lambda: js.least_squares(pendulum(), residuals, ["EA"], tol=0.0),
        ["`tol`", "0.0", "> 0"],
    ),
]


def test_at_least_forty_cases():
    assert len({name for name, _, _ in CASES}) == len(CASES) >= 40


@pytest.mark.parametrize(
    "call, parts", [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_input_is_refused_by_name(call, parts):
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    for part in parts:
        assert part in message, (part, message)


def test_sweep_takes_good_members_to_the_solve():
    # The member checks refuse nothing valid: this sweep gets as far as the solve.
    with pytest.raises(AssertionError, match="solve was traced"):
        js.sweep(pendulum(), {"EA": [1e3, 2e3], "alpha": [0.0, 0.02]}, devices=1)


# -- the command line: exit code 2, the message, no traceback

PENDULUM = ["run", "string-pendulum", "--k", "4", "--t1", "0.3"]

CLI_CASES = [
    ("k", PENDULUM + ["--k", "1"], ["`k`", "1", "integer >= 2"]),
    ("EA", PENDULUM + ["--EA", "nan"], ["`EA`", "nan", "> 0"]),
    ("alpha", PENDULUM + ["--alpha", "-1"], ["`alpha`", "-1.0", ">= 0"]),
    ("t1", PENDULUM + ["--t1", "0"], ["`t1`", "0.0", "> 0"]),
    ("theta0", PENDULUM + ["--theta0", "inf"], ["`theta0`", "inf", "finite"]),
    ("rtol", PENDULUM + ["--rtol", "0"], ["`rtol`", "0.0", "> 0"]),
    ("atol", PENDULUM + ["--atol=-1e-6"], ["`atol`", "-1e-06", "> 0"]),
    ("frames", PENDULUM + ["--frames", "1"], ["--frames", "1", "integer >= 2"]),
    ("tether-N", ["run", "tether-fixed", "--N", "1"], ["`N`", "1", "integer >= 2"]),
    (
        "tether-smoothing",
        ["run", "tether-fixed", "--N", "6", "--smoothing", "-1"],
        ["`smoothing`", "-1.0", ">= 0"],
    ),
    (
        "tether-k-lms",
        ["run", "tether-fixed", "--N", "6", "--method", "lms", "--k-lms", "-1"],
        ["`k_lms`", "-1.0", "> 0"],
    ),
    (
        "winch-t1",
        ["run", "tether-winch", "--N", "6", "--t1", "nan"],
        ["`t1`", "nan", "> 0"],
    ),
    (
        "tandem-hawser",
        ["run", "tandem-hopf", "--hawser", "line"],
        ["--hawser", "'line'", "'massless'"],
    ),
    (
        "tandem-animate",
        ["run", "tandem-equilibria", "--animate"],
        ["--animate", "tandem-equilibria", "tandem-fishtail"],
    ),
]


@pytest.mark.parametrize(
    "argv, parts", [c[1:] for c in CLI_CASES], ids=[c[0] for c in CLI_CASES]
)
def test_cli_bad_option_exits_2(argv, parts, tmp_path, capsys):
    code = main(argv + ["--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert code == 2
    assert captured.err.startswith("error:")
    assert "Traceback" not in captured.err
    for part in parts:
        assert part in captured.err, (part, captured.err)
    assert not (tmp_path / "out").exists()


def test_cli_unwritable_output_exits_2(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    code = main(PENDULUM + ["--out", str(blocker / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert "--out" in err and str(blocker / "out") in err
    assert "Traceback" not in err


@pytest.mark.parametrize(
    "argv, parts",
    [
        (PENDULUM + ["--k", "2.5"], ["--k", "'2.5'"]),
        (PENDULUM + ["--solver", "rk4"], ["--solver", "'rk4'", "kvaerno5"]),
        (PENDULUM + ["--formulation", "nat"], ["--formulation", "'nat'", "natural"]),
        (["run", "no-such-scene"], ["SCENE", "'no-such-scene'", "string-pendulum"]),
    ],
    ids=["k-text", "solver", "formulation", "scene"],
)
def test_cli_parser_errors_exit_2(argv, parts, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert "Traceback" not in err
    for part in parts:
        assert part in err, (part, err)


def test_no_compilation_before_a_refusal():
    # The checks compile nothing: no XLA executable is built between the call and
    # its refusal (the scene is built before; building it runs eager kernels).
    base = pendulum()
    compiled = []

    def listen(event, duration, **kwargs):
        del duration, kwargs
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(event)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        for call in (
            lambda: js.simulate(base, ts=TS_OUT),
            lambda: js.sweep(base, {"EA": [1e3, -1e3]}),
            lambda: js.sweep(base, {"EA": [1e3, 2e3]}, ts=TS_DOWN),
            lambda: js.fit(base, loss, ["EA"], steps=0),
            lambda: js.least_squares(base, residuals, ["EA"], ts=TS_OUT),
        ):
            with pytest.raises(ValueError):
                call()
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert compiled == []
