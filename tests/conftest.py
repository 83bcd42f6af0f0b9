import os
import pathlib


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import pytest  # noqa: E402

import jaxstring  # noqa: E402, F401  (float64 on)


# JAX's persistent compilation cache. JAXSTRING_TEST_CACHE=<dir> keeps one across
# local runs. Otherwise the two xdist workers of a run, and the processes their
# tests start, share one in the run's temporary folder (pytest keeps the last
# three): a program that one process compiled (the same scene structure and
# solver in another test file) is read back by the others instead of compiled
# again; nothing is read from or written to
# the user's ~/.cache/jaxstring (JAXSTRING_CACHE=off: jaxstring's own default
# cache stays off, in this process and in the processes the tests start).
_cache = os.environ.get("JAXSTRING_TEST_CACHE")
os.environ.setdefault("JAXSTRING_CACHE", "off")


@pytest.fixture(scope="session", autouse=True)
def _shared_compilation_cache(tmp_path_factory):
    if _cache:
        folder = pathlib.Path(_cache).resolve()
    else:
        base = tmp_path_factory.getbasetemp()
        # under xdist each worker's folder is <run>/popen-gw<i>: share <run>
        run = base.parent if base.name.startswith("popen-gw") else base
        folder = run / "jax-compilation-cache"
    folder.mkdir(parents=True, exist_ok=True)
    settings = {
        "jax_compilation_cache_dir": str(folder),
        "jax_persistent_cache_min_compile_time_secs": 1.0,
        "jax_persistent_cache_min_entry_size_bytes": 0,
    }
    for name, value in settings.items():
        jax.config.update(name, value)
    # ... and the processes the tests start (the command, worker pools,
    # jax.distributed processes, the README's examples) share it too.
    saved = {name.upper(): os.environ.get(name.upper()) for name in settings}
    os.environ.update({name.upper(): str(v) for name, v in settings.items()})
    yield
    jax.config.update("jax_compilation_cache_dir", None)
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


# Files in the order of their measured cost, costliest first (the last full
# profile of the default run, experiments/results/suite_profile_tests.csv), so that
# xdist's file-by-file distribution does not leave one long file running alone at
# the end; files without a measurement keep their place after the measured ones.
_PROFILE = (
    pathlib.Path(__file__).resolve().parents[1]
    / "experiments"
    / "results"
    / "suite_profile_tests.csv"
)


def _file_costs():
    import csv
    import io

    costs = {}
    try:
        text = _PROFILE.read_text()
    except OSError:
        return costs
    lines = [line for line in text.splitlines() if not line.startswith("#")]
    rows = csv.DictReader(io.StringIO("\n".join(lines)))
    for row in rows:
        try:
            name, wall = row["test"].split("::")[0], float(row["wall_s"])
        except (KeyError, ValueError, AttributeError):
            continue
        costs[name] = costs.get(name, 0.0) + wall
    return costs


def pytest_collection_modifyitems(config, items):
    costs = _file_costs()
    if not costs:
        return
    root = pathlib.Path(str(config.rootpath))

    def cost(item):
        try:
            name = pathlib.Path(str(item.path)).relative_to(root).as_posix()
        except ValueError:
            return 0.0
        return costs.get(name, 0.0)

    items.sort(key=lambda item: -cost(item))  # stable: a file's tests keep order
