import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring.cli.main import main


FAST = ["run", "string-pendulum", "--k", "6", "--EA", "1e4", "--t1", "0.3"]


def test_run_string_pendulum(tmp_path, capsys):
    code = main(FAST + ["--alpha", "0.01", "--no-cache", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0
    assert "status" in out and "success" in out
    png = tmp_path / "string_pendulum.png"
    npz = tmp_path / "string_pendulum.npz"
    assert png.exists() and png.stat().st_size > 0
    assert npz.exists()
    with np.load(npz) as data:
        energy = data["energy"]
        assert energy.shape == data["ts"].shape
        assert np.all(np.isfinite(energy))
        assert bool(data["ok"])
        assert float(data["alpha"]) > 0
        # Kelvin-Voigt damping only removes energy.
        assert energy[-1] <= energy[0] + 1e-9
        assert data["positions"].shape[1:] == (7, 2)


def test_bad_input_exits_2(tmp_path, capsys):
    argv = ["run", "string-pendulum", "--EA", "-1", "--out", str(tmp_path)]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error:")
    assert "EA" in err
    assert not (tmp_path / "string_pendulum.npz").exists()


def test_unknown_scene_lists_valid(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "no-such-scene"])
    assert exc.value.code == 2
    assert "string-pendulum" in capsys.readouterr().err


def test_command_caches_the_compiled_solve(tmp_path):
    # The `jaxstring` command runs with EQX_ON_ERROR=nan, so its solve has no host
    # callbacks: its traced program and its executable are saved in the cache
    # folder, and a second process runs the executable instead of compiling.
    import os
    import subprocess
    import sys

    exe = os.path.join(os.path.dirname(sys.executable), "jaxstring")
    if not os.path.exists(exe):
        pytest.skip("the jaxstring command is not installed beside this python")
    cache = tmp_path / "cache"
    # (the tests' JAXSTRING_CACHE=off and shared JAX cache left out: the
    # command's default is on, in its own folder)
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("EQX_ON_ERROR", "JAXSTRING_CACHE")
        and not k.startswith("JAX_PERSISTENT_CACHE")
        and k != "JAX_COMPILATION_CACHE_DIR"
    }
    env["JAXSTRING_CACHE_DIR"] = str(cache)
    cmd = [exe, *FAST, "--out", str(tmp_path / "out")]

    def files():
        return sorted(str(f.relative_to(cache)) for f in cache.rglob("*"))

    first = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    saved = files()
    assert [f for f in saved if f.endswith(".program")]
    assert [f for f in saved if f.endswith(".full.executable")]
    second = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert second.returncode == 0, second.stderr
    # Nothing new traced or compiled (no new cache entries), the same result.
    assert files() == saved
    end = [ln for ln in first.stdout.splitlines() if ln.startswith("end mass")]
    assert end and end == [
        ln for ln in second.stdout.splitlines() if ln.startswith("end mass")
    ]


def test_saved_program_runs_without_tracing_and_gives_the_same_result(tmp_path):
    # A function saved as a program is traced once; after JAX's in-memory caches
    # are cleared (as in a new process) it is loaded and run, not traced again.
    import jax
    import jax.numpy as jnp

    from jaxstring import _programs

    traces = []

    def fn(x, scale):
        traces.append(1)
        return {"y": jnp.cumsum(jnp.sin(x) * scale), "n": jnp.sum(x > 0)}

    def with_callback(v):
        return {"y": jax.pure_callback(lambda a: a, v, v)}

    x = jnp.linspace(-1.0, 2.0, 7)
    _programs.set_program_folder(str(tmp_path))
    try:
        first = _programs.call(fn, x, jnp.asarray(2.0))
        jax.clear_caches()
        _programs._LOADED.clear()  # as in a new process: read the saved file
        second = _programs.call(fn, x, jnp.asarray(2.0))
        other = _programs.call(fn, x, jnp.asarray(3.0))  # new values, same program
        bad = _programs.call(with_callback, x)
        unnamed = _programs.call(lambda v: {"y": 2.0 * v}, x)
    finally:
        _programs.set_program_folder(None)
    assert len(traces) == 1
    assert len(list(tmp_path.glob("*.program"))) == 1
    expected = jnp.cumsum(jnp.sin(x) * 2.0)
    assert jnp.array_equal(first["y"], expected) and jnp.array_equal(
        second["y"], expected
    )
    assert jnp.allclose(other["y"], 1.5 * expected, rtol=1e-15, atol=1e-15)
    assert int(second["n"]) == 4  # 0.5, 1, 1.5, 2
    assert bad is None  # host callbacks: no program, the caller runs it its own way
    assert unnamed is None  # a lambda has no name to key its program by


def test_saved_programs_of_two_solver_classes_of_one_name_are_two(tmp_path):
    # diffrax's Kvaerno5 and jaxstring's print alike: the saved program's key
    # tells them apart by module, or a solve would run the other solver's program.
    import diffrax as dfx

    from jaxstring import _programs

    def fn(x, config):
        return {"y": x * (2.0 if isinstance(config.solver, js.Kvaerno5) else 3.0)}

    x = jnp.ones(3)
    _programs.set_program_folder(str(tmp_path))
    try:
        ours = _programs.call(fn, x, js.SolveConfig(solver=js.Kvaerno5()))
        theirs = _programs.call(fn, x, js.SolveConfig(solver=dfx.Kvaerno5()))
    finally:
        _programs.set_program_folder(None)
    assert repr(js.Kvaerno5()) == repr(dfx.Kvaerno5())
    assert float(ours["y"][0]) == 2.0 and float(theirs["y"][0]) == 3.0
    assert len(list(tmp_path.glob("*.program"))) == 2


@pytest.mark.parametrize(
    "extra, named",
    [
        (["--ramp", "5"], "--ramp"),  # no motion table to ramp in
        (["--motion", "ZZP1_A1.txt", "--ramp", "-1"], "--ramp"),
        (["--axial-drag", "area"], "axial-drag"),
    ],
)
def test_moordyn_bad_options_exit_2(tmp_path, capsys, extra, named):
    from jaxstring import lines

    deck = lines.case_path("WD0050_Chain.txt")
    extra = [
        lines.case_path("QuasiStatic/ZZP1_A1.txt") if a == "ZZP1_A1.txt" else a
        for a in extra
    ]
    argv = ["run", "moordyn", deck, "--out", str(tmp_path), *extra]
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse refuses an invalid choice
        code = exc.code
    assert code == 2
    assert named in capsys.readouterr().err
    assert not list(tmp_path.glob("*.out"))


def test_sweep_writes_a_table_per_member(tmp_path, capsys):
    argv = ["sweep", "string-pendulum", "--k", "4", "--t1", "0.2", "--solver", "bdf",
            "--vary", "alpha=0.005:0.05:4", "--batch-size", "2", "--processes", "1",
            "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    lines = (tmp_path / "string-pendulum_sweep.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[:4] == ["alpha", "ok", "status", "accepted_steps"]
    assert len(lines) == 5  # one row per member, in the given order
    alphas = [float(row.split(",")[0]) for row in lines[1:]]
    np.testing.assert_allclose(alphas, np.linspace(0.005, 0.05, 4))
    with np.load(tmp_path / "string-pendulum_sweep.npz") as data:
        assert data["ok"].all()
        # More damping, less energy left at the end (a physical check per member).
        assert np.all(np.diff(data["energy_end_J"]) < 0)
    assert (tmp_path / "string-pendulum_sweep.png").stat().st_size > 0


@pytest.mark.parametrize(
    "vary, part",
    [
        ("alpha=1:2", "NAME=LOW:HIGH:COUNT"),
        ("alpha=a:2:3", "must be numbers"),
        ("alpha=1:2:0", "COUNT must be >= 1"),
        ("nonsense=1:2:3", "unknown parameter 'nonsense'"),
    ],
)
def test_sweep_bad_vary_exits_2(tmp_path, capsys, vary, part):
    argv = ["sweep", "string-pendulum", "--k", "4", "--t1", "0.1", "--vary", vary,
            "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 2
    assert part in capsys.readouterr().err


def test_saved_programs_of_two_functions_with_the_same_arguments_are_two(tmp_path):
    # The key holds the function's name: two functions of the same arguments
    # (the equilibria's and the solve's, say) do not run each other's program.
    from jaxstring import _programs

    def double(x):
        return {"y": 2.0 * x}

    def triple(x):
        return {"y": 3.0 * x}

    x = jnp.arange(4.0)
    _programs.set_program_folder(str(tmp_path))
    try:
        two, three = _programs.call(double, x), _programs.call(triple, x)
    finally:
        _programs.set_program_folder(None)
    assert len(list(tmp_path.glob("*.program"))) == 2
    assert jnp.array_equal(two["y"], 2.0 * x) and jnp.array_equal(three["y"], 3.0 * x)


_SOLVE_MODULE = """
import jax.numpy as jnp

TRACES = []


def solve(a, b):
    TRACES.append(1)
    return {"x": jnp.linalg.solve(a, b), "det": jnp.linalg.det(a)}
"""

_SOLVE_DRIVER = """
import json, sys
import numpy as np
import jax.numpy as jnp
import jaxstring
from jaxstring import _programs
import solve_module

folder, mode = sys.argv[1], sys.argv[2]
_programs.set_program_folder(folder)
if mode == "executable only":
    def refuse(*args):
        raise AssertionError("the traced program was read")
    _programs._exported = refuse
if mode == "trace, into JAX's cache too":
    import contextlib
    from jaxstring import _executables
    _executables._no_cache_write = contextlib.nullcontext
a = np.array([[4.0, 1.0, 0.5], [2.0, 3.0, 1.0], [0.0, 1.0, 5.0]])
b = np.array([1.0, 2.0, 3.0])
out = _programs.call(solve_module.solve, jnp.asarray(a), jnp.asarray(b))
print(json.dumps({"x": np.asarray(out["x"]).tolist(), "det": float(out["det"]),
                  "traces": len(solve_module.TRACES)}))
"""


def _run_solve_driver(tmp_path, folder, mode, jax_cache=None):
    import json
    import os
    import subprocess
    import sys

    (tmp_path / "solve_module.py").write_text(_SOLVE_MODULE)
    (tmp_path / "driver.py").write_text(_SOLVE_DRIVER)
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}
    env["PYTHONPATH"] = str(tmp_path)
    if jax_cache is not None:
        env["JAX_COMPILATION_CACHE_DIR"] = str(jax_cache)
        env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
        env["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "0"
    run = subprocess.run(
        [sys.executable, str(tmp_path / "driver.py"), str(folder), mode],
        env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    return json.loads(run.stdout.splitlines()[-1])


def test_a_later_process_runs_the_saved_executable_without_the_traced_program(
    tmp_path,
):
    # The first process traces, compiles and saves the program and its
    # executable; a fresh process (no JAX compilation cache) runs the executable
    # without reading the traced program. The program solves with LAPACK's LU,
    # which a process that has lowered nothing must make ready before the run
    # (it crashed on a null routine without it).
    folder = tmp_path / "programs"
    folder.mkdir()
    first = _run_solve_driver(tmp_path, folder, "trace")
    assert first["traces"] == 1
    assert len(list(folder.glob("*.program"))) == 1
    assert len(list(folder.glob("*.full.executable"))) == 1
    second = _run_solve_driver(tmp_path, folder, "executable only")
    a = np.array([[4.0, 1.0, 0.5], [2.0, 3.0, 1.0], [0.0, 1.0, 5.0]])
    b = np.array([1.0, 2.0, 3.0])
    assert second["traces"] == 0
    np.testing.assert_allclose(second["x"], np.linalg.solve(a, b), rtol=1e-14)
    np.testing.assert_allclose(second["det"], np.linalg.det(a), rtol=1e-14)
    assert second == first | {"traces": 0}
    # An executable that cannot be read is compiled again from the traced
    # program and rewritten.
    (executable,) = folder.glob("*.full.executable")
    executable.write_bytes(b"not an executable")
    third = _run_solve_driver(tmp_path, folder, "trace")
    assert third == second
    assert executable.stat().st_size > 1000


_PLAIN_DRIVER = """
import json, sys
import jax
import jax.numpy as jnp
from jaxstring import _executables, _programs

events = []
jax.monitoring.register_event_duration_secs_listener(
    lambda name, secs, **kw: events.append((name, kw.get("fun_name", ""))))
lowerings = []
export = _executables.export_with_lowering
def counted(*args):
    exported, lowered = export(*args)
    lowerings.append(lowered is not None)
    return exported, lowered
_executables.export_with_lowering = counted

def decay(y0, rate):
    def step(_, y):
        return y - 0.01 * rate * y
    return {"y": jax.lax.fori_loop(0, 100, step, y0)}

_programs.set_program_folder(sys.argv[1])
out = _programs.call(decay, jnp.linspace(1.0, 2.0, 5), jnp.asarray(3.0))
saved = [n for n, f in events if n.endswith("jaxpr_to_mlir_module_duration")
         and "saved_" in f]
print(json.dumps({"y": [float(v).hex() for v in out["y"]], "lowerings": lowerings,
                  "saved_lowerings": len(saved),
                  "lapack_loaded": "scipy.linalg" in sys.modules}))
"""


def test_a_process_that_traces_a_program_compiles_the_exports_own_lowering(
    tmp_path,
):
    # The process that traces a saved program compiles the lowering that the
    # export made (one lowering, not a second one of the exported call), and so
    # does not load LAPACK's kernels for a program without them; the executable
    # it saves gives a later process the same values to the bit.
    import json
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}
    driver, folder = tmp_path / "plain_driver.py", tmp_path / "programs"
    driver.write_text(_PLAIN_DRIVER)  # (a function of a file is saved; of -c not)
    folder.mkdir()

    def run():
        out = subprocess.run(
            [sys.executable, str(driver), str(folder)],
            env=env, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert out.returncode == 0, out.stderr[-2000:]
        return json.loads(out.stdout.splitlines()[-1])

    first, second = run(), run()
    assert first["lowerings"] == [True] and first["saved_lowerings"] == 1
    assert not first["lapack_loaded"]
    assert len(list(folder.glob("*.full.executable"))) == 1
    assert second["lowerings"] == [] and second["saved_lowerings"] == 0
    assert second["y"] == first["y"]
    # y (1 - 0.03)^100, elementwise
    expected = np.linspace(1.0, 2.0, 5) * 0.97**100
    got = np.array([float.fromhex(v) for v in first["y"]])
    np.testing.assert_allclose(got, expected, rtol=1e-13)


def test_an_executable_read_from_jaxs_cache_is_not_saved(tmp_path):
    # A saved program's compilation goes to its program folder only, not to
    # JAX's compilation cache as well: a second process with another folder and
    # the same JAX cache compiles it and saves its own executable. Where a
    # compilation does come from JAX's cache (a pool's workers share theirs
    # there; here a first process made to write it), XLA:CPU serialises it
    # incompletely, so the program keeps its traced program only, and a later
    # process runs it from there.
    names = ("cache", "one", "two", "cache2", "three", "four")
    cache, one, two, cache2, three, four = (tmp_path / name for name in names)
    for folder in (cache, one, two, cache2, three, four):
        folder.mkdir()
    first = _run_solve_driver(tmp_path, one, "trace", jax_cache=cache)
    assert len(list(one.glob("*.full.executable"))) == 1
    assert not [f for f in cache.iterdir() if "saved_" in f.name]
    second = _run_solve_driver(tmp_path, two, "trace", jax_cache=cache)
    assert second["traces"] == 1
    assert len(list(two.glob("*.full.executable"))) == 1
    third = _run_solve_driver(
        tmp_path, three, "trace, into JAX's cache too", jax_cache=cache2
    )
    assert [f for f in cache2.iterdir() if "saved_" in f.name]
    fourth = _run_solve_driver(tmp_path, four, "trace", jax_cache=cache2)
    assert len(list(four.glob("*.program"))) == 1
    assert not list(four.glob("*.executable"))
    fifth = _run_solve_driver(tmp_path, four, "trace", jax_cache=cache2)
    assert fifth["traces"] == 0
    assert first["x"] == second["x"] == third["x"] == fourth["x"] == fifth["x"]


def test_eager_calls_are_saved_programs_that_a_later_process_reads(tmp_path):
    # A scene builder's compiled call (`eager_jit`: here the string's initial
    # state) is saved with the program folder set; after JAX's in-memory caches are
    # cleared (as in a new process) it is read back, not traced, and gives the same
    # state.
    import jax

    from jaxstring import _programs
    from jaxstring.pendulum import scenes

    traces = []
    body = scenes._initial_state.__wrapped__

    def counted(*args):
        traces.append(1)
        return body(*args)

    scene = js.string_pendulum(k=4, t1=0.1)
    theta0 = jnp.asarray(0.3)
    _programs.set_program_folder(str(tmp_path))
    try:
        first = scenes.eager_jit(counted)(scene.model, theta0)
        jax.clear_caches()
        _programs._LOADED.clear()
        again = scenes.eager_jit(counted)(scene.model, theta0)
    finally:
        _programs.set_program_folder(None)
    assert len(traces) == 1
    assert jnp.array_equal(first, again)
    # Nodes at rest on the line from the mount at 0.3 rad from the vertical, the
    # last at the string's 1 m length.
    x, y = first[:, 0], first[:, 1]
    assert jnp.allclose(jnp.arctan2(x, -y), 0.3, rtol=0, atol=1e-14)
    assert jnp.allclose(jnp.hypot(x, y), jnp.arange(1, 5) / 4, rtol=1e-14)
    assert not jnp.any(first[:, 2:])


def test_a_saved_program_of_a_users_own_class_follows_its_source(tmp_path):
    # A model or effect of the user's own is keyed by the file that defines it: a
    # program saved before that file changed is not run after. A class without a
    # source file (a notebook's) is not saved at all.
    import importlib.util
    import sys
    import types

    from jaxstring import _programs

    source = (
        "import equinox as eqx\n"
        "class Gain(eqx.Module):\n"
        "    k: float = eqx.field(static=True)\n"
    )
    path = tmp_path / "user_gain.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("user_gain", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["user_gain"] = module
    try:
        spec.loader.exec_module(module)
        before = _programs._full_key(_double, (module.Gain(2.0),), None, [])
        path.write_text(source + "# edited\n")
        after = _programs._full_key(_double, (module.Gain(2.0),), None, [])
    finally:
        sys.modules.pop("user_gain", None)
    notebook = types.ModuleType("notebook_cell")
    exec(source, notebook.__dict__)
    notebook.Gain.__module__ = "notebook_cell"
    sys.modules["notebook_cell"] = notebook
    try:
        unsaved = _programs._full_key(_double, (notebook.Gain(2.0),), None, [])
    finally:
        sys.modules.pop("notebook_cell")
    assert before is not None and after is not None and before != after
    assert unsaved is None


def _double(x):
    return {"y": 2.0 * x}


_WARM_DRIVER = """
import json, sys
import numpy as np
import jaxstring as js
scene = js.pendulum.string_pendulum(k=6, EA=1e4, t1=0.3)
traj = js.simulate(scene)
swept = js.sweep(scene, {"alpha": [0.01, 0.04]}, processes=1, n_save=4)
print(json.dumps({"end": np.asarray(traj.end_mass[-1]).tolist(), "ok": traj.ok,
                  "status": traj.status,
                  "swept": swept.out["positions"][:, -1, -1].tolist(),
                  "swept_ok": bool(swept.ok.all()),
                  "imported": [m for m in ("diffrax", "optimistix", "lineax")
                               if m in sys.modules]}))
"""


def test_a_later_process_runs_a_saved_solve_without_importing_diffrax(tmp_path):
    # A process that runs a saved solve or sweep neither traces nor builds a
    # solver, so it imports neither diffrax nor optimistix (`jaxstring._lazy`);
    # the first process, which traces them, does.
    import json
    import os
    import subprocess
    import sys

    # (as a user runs it: the tests' settings of equinox's checks and of the
    # caches left out)
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("EQX_ON_ERROR", "JAXSTRING_CACHE") and not k.startswith("JAX_")
    }
    env["JAXSTRING_CACHE_DIR"] = str(tmp_path / "cache")

    def run():
        out = subprocess.run(
            [sys.executable, "-c", _WARM_DRIVER],
            env=env, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert out.returncode == 0, out.stderr[-2000:]
        return json.loads(out.stdout.splitlines()[-1])

    first, second = run(), run()
    assert first["imported"] == ["diffrax", "optimistix", "lineax"]
    assert second["imported"] == []
    assert first["ok"] and second["ok"] and second["status"] == "success"
    assert second["end"] == first["end"]
    assert first["swept_ok"] and second["swept_ok"]
    assert second["swept"] == first["swept"]
    # released from the horizontal, the end mass first falls freely: g t^2 / 2,
    # whatever the string's damping
    fall = -0.5 * 9.81 * 0.3**2
    np.testing.assert_allclose(first["end"][1], fall, rtol=1e-2)
    np.testing.assert_allclose(np.array(first["swept"])[:, 1], fall, rtol=1e-2)


def test_modules_named_for_a_compilation_are_imported_while_it_runs():
    # The command imports its figure's modules while XLA compiles the solve: the
    # first compilation in the block starts them in a thread; a later one, and
    # one outside the block, start nothing.
    import sys
    import threading

    from jaxstring import _executables

    assert "tabnanny" not in sys.modules  # a standard module nothing here imports
    lowered = jax.jit(lambda x: 3.0 * x + 1.0).lower(1.0)
    with _executables.imports_while_compiling("tabnanny"):
        compiled = _executables.compile_and_save(lowered, None, "k", "full", False)
        assert not _executables._WHILE_COMPILING  # started once only
    for thread in threading.enumerate():
        if thread.name == "imports":
            thread.join(timeout=30)
    assert "tabnanny" in sys.modules
    assert float(compiled(2.0)) == 7.0
