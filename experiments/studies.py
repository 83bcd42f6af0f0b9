"""Every study of experiments/: its script, the runs that write its results files,
the expected run time, and the source code its results measure.

``run_all.py`` runs these (``--quick``: each script's quick run once); ``stale.py``
checks each results file against the code of the study that wrote it; the results
writer (``harness.py``) stamps each file with the fingerprint of that code. A new
study, or a new results file of a study, is added here.

``measures``: files or folders, relative to the repository root, whose code the
study's numbers depend on (the script itself is added). Standard library only.
"""

import dataclasses
import pathlib


@dataclasses.dataclass(frozen=True)
class Run:
    """One command of a study: `python experiments/<script>.py <args>`."""

    args: tuple = ()
    outputs: tuple = ()  # results files it writes (names in experiments/results/)
    gpu: bool = False  # run on a machine with a GPU only


@dataclasses.dataclass(frozen=True)
class Study:
    name: str  # the study's name (run_all.py --only NAME)
    script: str  # experiments/<script>
    question: str
    runtime: str  # expected wall time, quick / full, on the 2-core shared machine
    measures: tuple  # source paths whose code the results measure
    runs: tuple  # the full runs, in order (a later run may overwrite a file)
    quick: tuple = ((),)  # the arguments of the quick runs (with --quick added)

    @property
    def paths(self) -> tuple:
        """The measured paths, the script included."""
        return tuple(dict.fromkeys((f"experiments/{self.script}", *self.measures)))

    @property
    def outputs(self) -> tuple:
        return tuple(dict.fromkeys(o for r in self.runs for o in r.outputs))


def _files(*stems, ext=("md", "csv")):
    return tuple(f"{s}.{e}" for s in stems for e in ext)


# What a pendulum solve runs through.
SOLVE = (
    "jaxstring/_solvers",
    "jaxstring/_linalg",
    "jaxstring/_simulate.py",
    "jaxstring/_integrate.py",
    "jaxstring/_solve_config.py",
    "jaxstring/_model.py",
    "jaxstring/_scene.py",
    "jaxstring/_effect.py",
    "jaxstring/_jit.py",
    "jaxstring/_trajectory.py",
)
PENDULUM = (*SOLVE, "jaxstring/pendulum", "jaxstring/chain/effects.py")
PEERS = ("jaxstring/testing/peers.py",)
CALLBACKS = ("jaxstring/testing/references.py",)
TETHER = (*SOLVE, "jaxstring/tether", "jaxstring/chain")
TANDEM = (*SOLVE, "jaxstring/tandem", "jaxstring/chain")
FIT = ("jaxstring/_fit.py", "jaxstring/_least_squares.py", "jaxstring/_sensitivity.py")
LINES = (*SOLVE, "jaxstring/lines", "jaxstring/chain")
STATICS = (
    "jaxstring/lines/statics.py",
    "jaxstring/lines/catenary.py",
    "jaxstring/lines/bodies.py",
)

_RACE_PARTS = ("displacement_1e6", "displacement_1e9", "angle_1e6", "angle_1e9")
_SCALING = (
    (
        "displacement_release",
        "--formulation displacement --start release --ks 40,80,160,320,640,1280 "
        "--solvers bdf --peers cvode-numba --budget 200 --rounds 3",
    ),
    (
        "displacement_release_tol6",
        "--formulation displacement --ks 40,80,160,320,640,1280 --solvers bdf "
        "--peers none --rounds 3 --tol 1e-6 --budget 200",
    ),
    (
        "displacement_release_kvaerno5",
        "--formulation displacement --start release --ks 40,80,160,320,640,1280 "
        "--solvers kvaerno5 --repeats 1 --peers none --budget 150",
    ),
    (
        "displacement_swing_kvaerno5",
        "--formulation displacement --start swing --ks 40,80,160,320,640,1280 "
        "--solvers kvaerno5 --repeats 1 --peers none --budget 120",
    ),
    (
        "displacement_swing_bdf",
        "--formulation displacement --start swing --ks 40,80,160,320,640,1280 "
        "--solvers bdf --repeats 1 --peers none --budget 120",
    ),
)

STUDIES = (
    # -- the pendulum's timing studies (on harness.py) --------------------------
    Study(
        "bench_solvers",
        "bench_solvers.py",
        "every solver vs CVODE at rtol 1e-6 (k = 40, EA = 1e4/1e6/1e9), the k "
        "scaling of Rodas5P, the in-loop cost of a step's pieces",
        "1 min / 20 min",
        (*PENDULUM, *CALLBACKS),
        (
            Run(
                (),
                (
                    *_files("bench_solvers_scaling", "bench_solvers_components"),
                    "bench_solvers.png",
                ),
            ),
            Run(
                ("--solvers", "kvaerno5,kvaerno3,bdf,rodas5p", "--no-scaling"),
                _files("bench_solvers"),
            ),
            Run(
                (
                    "--solvers",
                    "theta,newmark,implicit_euler_fixed",
                    "--no-scaling",
                    "--suffix",
                    "_fixed",
                ),
                _files("bench_solvers_fixed"),
            ),
        ),
    ),
    Study(
        "bench_bdf",
        "bench_bdf.py",
        "the variable-order BDF against CVODE, Rodas5P and scipy's BDF",
        "1 min / 20-30 min",
        (*PENDULUM, *CALLBACKS),
        (Run((), _files("bench_bdf")),),
    ),
    Study(
        "work_precision",
        "work_precision.py",
        "end-mass error vs wall time per solver, tol 1e-3 ... 1e-9, against CVODE "
        "and Radau on callbacks",
        "20 s / 2 h",
        (*PENDULUM, *CALLBACKS),
        (
            Run(
                tuple(
                    "--formulations angle,displacement --EAs 1e6,1e9 --solvers "
                    "rodas5p,kvaerno5 --peers cvode-BDF,scipy-Radau --tols "
                    "1e-3,1e-5,1e-7,1e-9 --repeats 1".split()
                ),
                (
                    *_files("work_precision", "work_precision_headline"),
                    "work_precision.png",
                ),
            ),
            Run(
                tuple(
                    "--formulations displacement,angle --EAs 1e6,1e9 --solvers bdf "
                    "--peers cvode-BDF --tols 1e-3,1e-5,1e-7,1e-9 --repeats 1 "
                    "--name bdf".split()
                ),
                (
                    *_files("work_precision_bdf", "work_precision_headline_bdf"),
                    "work_precision_bdf.png",
                ),
            ),
        ),
    ),
    Study(
        "race_strongest",
        "race_strongest.py",
        "time to reach end-mass errors 1e-3 ... 1e-6 m against CVODE-numba and "
        "scipy on the numba peer (one process per scene, then one report)",
        "1 min / 60 min",
        (*PENDULUM, *PEERS, *CALLBACKS),
        (
            *(
                Run(
                    (
                        "--formulations",
                        part.split("_")[0],
                        "--EAs",
                        part.split("_")[1],
                        "--repeats",
                        "3",
                        "--name",
                        part,
                    ),
                    _files(f"race_strongest_{part}", ext=("md", "csv", "png")),
                )
                for part in _RACE_PARTS
            ),
            Run(
                ("--merge", ",".join(_RACE_PARTS)),
                _files("race_strongest", ext=("md", "csv", "png")),
            ),
        ),
    ),
    Study(
        "race_strongest_presets",
        "race_strongest.py",
        "the accuracy presets: fastest solver and tolerance per system that "
        "reaches 1e-3/1e-5/1e-7 m (writes jaxstring/presets.json)",
        "1 min / 35 min",
        (*PENDULUM, *TETHER, *TANDEM, *PEERS),
        (
            Run(("--presets",), _files("race_strongest_presets")),
            Run(("--presets", "tandem"), _files("race_strongest_presets_tandem")),
        ),
        quick=(("--presets",),),
    ),
    Study(
        "fig9_formulations",
        "fig9_formulations.py",
        "paper Fig 9: run time vs EA per formulation at rtol 1e-7, against "
        "CVODE-numba and IDA on callbacks",
        "15 s / 10 min",
        (*PENDULUM, *PEERS, *CALLBACKS),
        (Run((), _files("fig9_formulations", ext=("md", "csv", "png"))),),
    ),
    Study(
        "fig10_integrators",
        "fig10_integrators.py",
        "paper Fig 10: every integrator vs EA at the paper's settings, and where "
        "the implicit time goes",
        "30 s / 10 min",
        (*PENDULUM, *PEERS, *CALLBACKS),
        (
            Run(
                ("--repeats", "3"),
                (
                    *_files("fig10_integrators", ext=("md", "csv", "png")),
                    *_files("fig10_where_time_goes"),
                ),
            ),
        ),
    ),
    Study(
        "scaling_k",
        "scaling_k.py",
        "run time vs k = 10 ... 1280 with fitted exponents, against CVODE-numba",
        "45 s / 3 h (six runs)",
        (*PENDULUM, *PEERS, *CALLBACKS),
        (
            *(
                Run(
                    (*args.split(), "--name", name),
                    (
                        *_files(f"scaling_k_{name}", ext=("md", "csv", "png")),
                        *_files(f"scaling_k_exponents_{name}"),
                    ),
                )
                for name, args in _SCALING
            ),
            Run(
                ("--rounds", "3"),
                (
                    *_files("scaling_k", ext=("md", "csv", "png")),
                    *_files("scaling_k_exponents"),
                ),
            ),
        ),
    ),
    Study(
        "step_cost",
        "step_cost.py",
        "where a BDF step's time goes at k = 40 ... 1280",
        "1 min / 5 min",
        PENDULUM,
        (Run((), _files("step_cost", ext=("md", "csv", "png"))),),
    ),
    Study(
        "esdirk_step",
        "esdirk_step.py",
        "Kvaerno5 written out against diffrax's Runge-Kutta loop",
        "30 s / 20 min",
        PENDULUM,
        (Run((), _files("esdirk_step")),),
    ),
    # -- other timing studies ----------------------------------------------------
    Study(
        "references",
        "references.py",
        "scipy and SUNDIALS on jaxstring's JAX functions through callbacks, each "
        "Jacobian variant, on one scene",
        "40 s / 5 min",
        (*PENDULUM, *CALLBACKS),
        (Run((), _files("references")),),
    ),
    Study(
        "compile_time",
        "compile_time.py",
        "compile time of a pendulum simulate per solver",
        "1 min / 2 min",
        (*PENDULUM, "jaxstring/_config.py"),
        (Run((), _files("compile_time")),),
    ),
    Study(
        "ynn_fusion",
        "ynn_fusion.py",
        "banded Jacobian, factorisation and solve with and without YNNPACK fusions",
        "1 min / 5 min",
        PENDULUM,
        (Run((), _files("ynn_fusion", ext=("md", "csv", "png"))),),
    ),
    Study(
        "blas_threads",
        "blas_threads.py",
        "LU with OpenBLAS at one thread per core, behind jaxstring's guard, and at "
        "one thread",
        "15 s / 30 s",
        ("jaxstring/__init__.py", "jaxstring/_config.py"),
        (Run((), _files("blas_threads", ext=("md", "csv", "png"))),),
    ),
    Study(
        "slack_snap",
        "slack_snap.py",
        "the slack string snapping taut: sharp and smoothed tension-only law",
        "k = 10 / 40 min",
        (*PENDULUM, *PEERS, *FIT),
        (
            Run(
                (),
                (
                    *_files("slack_snap", "slack_snap_smoothing"),
                    "slack_snap.png",
                    "slack_snap_steps.csv",
                ),
            ),
            Run(("--k_large", "160", "--large_only"), _files("slack_snap_k160")),
            Run(("--gradients_only",), _files("slack_snap_gradients")),
        ),
    ),
    Study(
        "gradient_cost",
        "gradient_cost.py",
        "cost of a gradient relative to the forward solve",
        "1 min / 15 min",
        (*PENDULUM, *FIT),
        (Run((), _files("gradient_cost", ext=("md", "csv", "png"))),),
    ),
    Study(
        "sweep_speed",
        "sweep_speed.py",
        "64 alpha values: loop vs vmap vs lockstep sweeps",
        "2 min / 13 min",
        (*PENDULUM, "jaxstring/_sweep.py"),
        (
            Run(
                (),
                (
                    *_files("sweep_speed", "sweep_speed_profile"),
                    "sweep_speed.png",
                ),
            ),
            Run(("--failure-only",), _files("sweep_speed_failure")),
        ),
    ),
    Study(
        "sweep_race",
        "sweep_race.py",
        "a 64-member sweep against 64 CVODE-numba runs",
        "1 min / 40 min (GPU run: 3.5 min)",
        (*PENDULUM, *PEERS, "jaxstring/_sweep.py"),
        (
            Run(("--solver", "bdf", "--mode", "vmap"), _files("sweep_race")),
            Run(
                tuple(
                    "--ks 20,40 --members 1024 --peer-members 64 --group 1024 "
                    "--repeats 1 --name sweep_race_gpu".split()
                ),
                _files("sweep_race_gpu"),
                gpu=True,
            ),
        ),
    ),
    # -- paper reproductions and model checks ----------------------------------
    Study(
        "hard_cases",
        "hard_cases.py",
        "does every stiff, slack or violent case end in success or a clear status",
        "3 min / 2 h",
        (*PENDULUM, *TETHER, *TANDEM),
        (
            Run(("--k", "10"), _files("hard_cases", ext=("md", "csv", "png"))),
            Run(("--k", "40"), _files("hard_cases", ext=("md", "csv", "png"))),
            Run(
                tuple(
                    "--families pendulum --k 160 --formulations natural3d,angle".split()
                ),
                _files("hard_cases", ext=("md", "csv", "png")),
            ),
        ),
    ),
    Study(
        "pendulum_checks",
        "pendulum_checks.py",
        "the measured numbers behind the string-pendulum tests",
        "1 min / 3 min",
        (*PENDULUM, "tests/helpers.py", "tests/pendulum/test_physics.py"),
        (Run((), ("pendulum_checks.md",)),),
    ),
    Study(
        "moordyn_pendulum",
        "moordyn_pendulum.py",
        "MoorDyn's test-suite pendulum in MoorDyn and in jaxstring",
        "40 s / 5 min",
        PENDULUM,
        (
            Run(
                ("--repeats", "1"),
                _files("moordyn_pendulum", ext=("md", "csv", "png")),
            ),
        ),
    ),
    Study(
        "moordyn_cases",
        "moordyn_cases.py",
        "MoorDyn's validation decks in MoorDyn and in jaxstring.lines",
        "5 min / 40 min",
        (*LINES, *FIT),
        (
            Run(("--repeats", "2"), _files("moordyn_cases", ext=("md", "csv", "png"))),
            Run(("--chain-study",), _files("moordyn_cases_chain")),
            Run(("--gradients",), _files("moordyn_cases_gradients")),
            Run(("--identify",), _files("moordyn_cases_identify")),
        ),
    ),
    Study(
        "moordyn_bodies",
        "moordyn_bodies.py",
        "MoorDyn's body, rod and beam test decks in MoorDyn and in jaxstring.lines: "
        "the tested quantity in both codes, against the analytic value, wall times",
        "5 min / 8 min",
        LINES,
        (
            Run(
                (),
                (
                    *_files("moordyn_bodies"),
                    *_files(
                        "moordyn_bodies_orbit",
                        "moordyn_bodies_pinned",
                        "moordyn_bodies_beams",
                        ext=("png",),
                    ),
                ),
            ),
            Run(("--whole-loops",), _files("moordyn_bodies_whole_loops")),
        ),
    ),
    Study(
        "moordyn_solvers",
        "moordyn_solvers.py",
        "every solver on every MoorDyn deck from its own start: finished, "
        "finite, steps (hard cases stay stable)",
        "1 min / 20 min",
        LINES,
        (Run((), _files("moordyn_solvers")),),
    ),
    Study(
        "statics_moorpy",
        "statics_moorpy.py",
        "catenary statics (equilibrium, coupled stiffness, gradients) of the OC3 "
        "mooring against MoorPy: agreement and cost",
        "1 min / 3 min",
        (*STATICS, "jaxstring/testing/moorpy_peer.py"),
        (Run((), _files("statics_moorpy", "statics_moorpy_gradient")),),
    ),
    Study(
        "mooring_design",
        "mooring_design.py",
        "line length and anchor radius of the OC3 spar's mooring for a surge "
        "stiffness and a tension limit, by Newton on the exact statics",
        "2 min / 3 min",
        STATICS,
        (Run((), _files("mooring_design", ext=("md", "csv", "png"))),),
    ),
    Study(
        "tanker_equilibria",
        "tanker_equilibria.py",
        "spec S1: tandem equilibria over wind speed and angle",
        "40 s / 11 min",
        TANDEM,
        (
            Run(
                ("--methods",),
                (
                    *_files("tanker_equilibria", "tanker_equilibria_methods"),
                    "tanker_equilibria.png",
                ),
            ),
        ),
    ),
    Study(
        "tanker_hopf",
        "tanker_hopf.py",
        "spec S3b: the Hopf point and the limit cycles",
        "20 s / 26 s",
        TANDEM,
        (
            Run(
                (),
                (
                    *_files("tanker_hopf"),
                    *(
                        f"tanker_hopf_{s}.png"
                        for s in ("0kN", "20kN", "35kN", "40kN", "sweep")
                    ),
                ),
            ),
        ),
    ),
    Study(
        "tanker_line",
        "tanker_line.py",
        "the hawser as a tether chain: S2 eigenvalues, S3a limit cycle, S4",
        "2 min / 20 min",
        (*TANDEM, *TETHER),
        (
            Run((), (*_files("tanker_line"), "tanker_line.png")),
            Run(("--controlled",), _files("tanker_line_controlled")),
        ),
    ),
    Study(
        "dynamic_turret",
        "dynamic_turret.py",
        "the FPSO on its turret's lines integrated with the hull vs quasi-static",
        "3 min / 10 min",
        (*TANDEM, *LINES),
        (Run((), _files("dynamic_turret")),),
    ),
    Study(
        "tanker_controlled",
        "tanker_controlled.py",
        "spec S4: the compensator in four environments, model mismatch",
        "50 s / 2.5 min",
        TANDEM,
        (
            Run(
                (),
                (
                    *_files("tanker_controlled"),
                    *(
                        f"tanker_controlled_{s}.png"
                        for s in ("current", "wind15_180", "wind15_90", "wind5_0")
                    ),
                ),
            ),
            Run(("--mismatch",), _files("tanker_controlled_mismatch")),
        ),
    ),
    Study(
        "tether_compare",
        "tether_compare.py",
        "the tether: ACEAM vs exact constraint tensions vs LMS",
        "4 min / 10 min",
        TETHER,
        (
            Run(
                (),
                (
                    *_files("tether_compare", ext=("md", "csv", "png")),
                    "tether_fixed.png",
                    "tether_winch.png",
                    "tether_sharp_bend.csv",
                    "tether_winch_joins.csv",
                ),
            ),
        ),
    ),
    Study(
        "tether_moordyn",
        "tether_moordyn.py",
        "the paper's tether as a MoorDyn line and in jaxstring",
        "1.5 min / 15 min",
        TETHER,
        (Run((), _files("tether_moordyn", ext=("md", "csv", "png"))),),
    ),
    # -- differentiable use ------------------------------------------------------
    Study(
        "identify_pendulum",
        "identify_pendulum.py",
        "identify alpha (and EA) from noisy positions of a bouncing pendulum",
        "2 min / 10 min",
        (*PENDULUM, *FIT),
        (Run((), _files("identify_pendulum", ext=("md", "csv", "png"))),),
    ),
    Study(
        "identify_least_squares",
        "identify_least_squares.py",
        "alpha and EA by least_squares from 0.5 mm noisy positions, 20 seeds",
        "2 min / 15 min",
        (*PENDULUM, *FIT, "tests/pendulum/test_reference_scipy.py"),
        (
            Run((), _files("identify_least_squares", ext=("md", "csv", "png"))),
            Run(("--adam",), _files("identify_least_squares_adam")),
        ),
    ),
    Study(
        "identify_parallel",
        "identify_parallel.py",
        "least_squares and fit on 4 experiments over 1 and 2 worker processes",
        "1 min / 10 min",
        (
            *PENDULUM,
            *FIT,
            "jaxstring/_distribute.py",
            "jaxstring/_worker.py",
        ),
        (
            Run((), _files("identify_parallel")),
            Run(("--fit",), _files("identify_parallel_fit")),
        ),
        quick=((), ("--fit",)),
    ),
    Study(
        "sweep_scale",
        "sweep_scale.py",
        "sweeps over worker processes against CVODE-numba over as many processes",
        "2 min / 30 min",
        (
            *PENDULUM,
            "jaxstring/_sweep.py",
            "jaxstring/_distribute.py",
            "jaxstring/_worker.py",
            "jaxstring/testing/peers.py",
        ),
        (
            Run((), _files("sweep_scale", ext=("md", "csv", "png"))),
            # On a GPU machine: its GPU, then its CPU cores alone.
            Run(
                tuple(
                    "--members 1024,65536 --peer-members 1024 "
                    "--one-call-from 65536 --name sweep_scale_gpu".split()
                ),
                _files("sweep_scale_gpu", ext=("md", "csv", "png")),
                gpu=True,
            ),
            Run(
                tuple(
                    "--cpu --members 1024 --workers 16 "
                    "--name sweep_scale_16core".split()
                ),
                _files("sweep_scale_16core"),
                gpu=True,
            ),
        ),
    ),
    Study(
        "sweep_profile",
        "sweep_profile.py",
        "where a sweep step's time goes: kernels by part of the BDF step",
        "20 s; GPU run: 1 min",
        (*PENDULUM, "jaxstring/_sweep.py"),
        (
            Run((), _files("sweep_profile", "sweep_profile_kernels")),
            Run(
                ("--members", "16384", "--t1", "0.5"),
                _files("sweep_profile_gpu", "sweep_profile_gpu_kernels"),
                gpu=True,
            ),
        ),
        quick=(),
    ),
    Study(
        "sweep_distributed",
        "sweep_distributed.py",
        "a sweep over two jax.distributed processes against one process",
        "3 min",
        (*PENDULUM, "jaxstring/_sweep.py", "jaxstring/_distribute.py"),
        (Run((), _files("sweep_distributed")),),
        quick=(),
    ),
    Study(
        "placement",
        "placement.py",
        "where one simulate or least_squares runs on a host with a GPU",
        "GPU run: 2.5 min",
        (*PENDULUM, *FIT, "jaxstring/_solve_config.py", "jaxstring/_programs.py"),
        (Run(("--repeats", "1"), _files("placement"), gpu=True),),
        quick=(),
    ),
    Study(
        "compile_options",
        "compile_options.py",
        "XLA:CPU compile options against compile and run time of four solves "
        "and of the run-once programs",
        "1 min / 13 min",
        (*PENDULUM, "jaxstring/lines", "jaxstring/tandem", "jaxstring/_jit.py"),
        (
            Run((), _files("compile_options")),
            Run(("--run-once",), _files("compile_options_run_once")),
        ),
    ),
    Study(
        "cpu_loops",
        "cpu_loops.py",
        "XLA:CPU's small-while-loop threshold against solve and compile time",
        "30 s / 10 min",
        (*PENDULUM, "jaxstring/lines", "jaxstring/_sweep.py", "jaxstring/_config.py"),
        (Run((), _files("cpu_loops")),),
    ),
    Study(
        "esdirk_compile",
        "esdirk_compile.py",
        "compile and run time of the written-out Kvaerno against another commit's",
        "1 min / 10 min",
        PENDULUM,
        (Run(("--ref", "cd90f54"), _files("esdirk_compile")),),
        quick=(("--ref", "cd90f54"),),
    ),
    Study(
        "block_elimination",
        "block_elimination.py",
        "block Thomas against block cyclic reduction: compile and run time, "
        "kernels and whole solves",
        "1 min / 3 min",
        PENDULUM,
        (Run((), _files("block_elimination", "block_elimination_solves")),),
    ),
    Study(
        "suite_profile",
        "suite_profile.py",
        "where the default test run's time goes: XLA compilation, tracing, lowering",
        "1 min / 20 min",
        ("jaxstring", "tests", "experiments/_suite_profile_plugin.py"),
        (Run((), (*_files("suite_profile"), "suite_profile_tests.csv")),),
    ),
    Study(
        "first_result",
        "first_result.py",
        "time to the first result of each README example, preset and the command, "
        "cold and warm cache",
        "2 min / 25 min",
        (
            *PENDULUM,
            *TETHER,
            *TANDEM,
            *LINES,
            "jaxstring/_programs.py",
            "jaxstring/_executables.py",
            "jaxstring/_worker.py",
            "jaxstring/_arrays.py",
            "jaxstring/_config.py",
        ),
        (
            Run((), _files("first_result")),
            Run(("--ref", "00dd603", "--rounds", "2"), _files("first_result_ref")),
            Run(
                (
                    "--ref",
                    "e603934",
                    "--rounds",
                    "3",
                    "--only",
                    "readme_sweep",
                    "sweep_default_pendulum",
                    "--name",
                    "first_result_ref_sweep",
                ),
                _files("first_result_ref_sweep"),
            ),
        ),
    ),
    Study(
        "solve_defaults",
        "solve_defaults.py",
        "the identification defaults: least squares at rtol 1e-6, 1e-7, 1e-8",
        "3 min / 8 min",
        (*PENDULUM, *FIT, "tests/pendulum/test_reference_scipy.py"),
        (Run((), _files("solve_defaults")),),
    ),
    Study(
        "identify_tandem",
        "identify_tandem.py",
        "the vessels' cross-flow drag coefficients from 3000 s of headings",
        "15 s / 1 min",
        (*TANDEM, *FIT),
        (Run((), _files("identify_tandem", ext=("md", "csv", "png"))),),
    ),
    Study(
        "identify_tether",
        "identify_tether.py",
        "the tether's drag coefficients from the running-end force",
        "3 min / 22 min",
        (*TETHER, *FIT),
        (
            Run((), _files("identify_tether", ext=("md", "csv", "png"))),
            Run(("--least-squares",), _files("identify_tether_least_squares")),
        ),
    ),
    Study(
        "tune_tanker",
        "tune_tanker.py",
        "law B's gains tuned by gradient descent through four S4 environments",
        "5 min / 20 min",
        (*TANDEM, *FIT),
        (Run((), _files("tune_tanker", ext=("md", "csv", "png"))),),
    ),
)

BY_NAME = {s.name: s for s in STUDIES}
RESULTS = pathlib.Path(__file__).resolve().parent / "results"


def study_for(filename: str):
    """The study that writes results file `filename` (a name in results/ or
    results/quick/, e.g. ``fig10_where_time_goes.md`` or a quick or variant run's
    ``scaling_k_quick.csv``): the one that lists it, else the one with the longest
    output stem that starts the name; None if no study claims it."""
    name = pathlib.Path(filename).name
    for study in STUDIES:
        if name in study.outputs:
            return study
    stem = name.rsplit(".", 1)[0]
    best, length = None, 0
    for study in STUDIES:
        for out in study.outputs:
            s = out.rsplit(".", 1)[0]
            if (stem == s or stem.startswith(s + "_")) and len(s) > length:
                best, length = study, len(s)
    return best
