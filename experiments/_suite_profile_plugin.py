"""pytest plugin of suite_profile.py: per test, its wall time and JAX's own
compile-time events (tracing, lowering, XLA compilation and their counts), written
per xdist worker to ``$SUITE_PROFILE_DIR/<worker>.json``."""

import collections
import json
import os
import pathlib
import time

import jax.monitoring
import pytest


EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace_s",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower_s",
    "/jax/core/compile/backend_compile_duration": "compile_s",
}

_current = {"test": None}
_data = collections.defaultdict(collections.Counter)


def _on_duration(event, seconds, **_):
    name = EVENTS.get(event)
    if name and _current["test"] is not None:
        _data[_current["test"]][name] += seconds
        if name == "compile_s":
            _data[_current["test"]]["compilations"] += 1


jax.monitoring.register_event_duration_secs_listener(_on_duration)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _current["test"] = item.nodeid
    start = time.perf_counter()
    yield
    _data[item.nodeid]["wall_s"] += time.perf_counter() - start
    _current["test"] = None


def pytest_sessionfinish(session):
    folder = pathlib.Path(os.environ["SUITE_PROFILE_DIR"])
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    (folder / f"{worker}.json").write_text(json.dumps(_data))
