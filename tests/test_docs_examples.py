"""The code blocks of README.md and docs/guide.md run as written, in order.

Each document's ```python blocks are joined into one script and run in a fresh
process (in a temporary folder, so that the files they write stay there). Where
the text allows, a few sizes are made smaller so that the run is quick: each
substitution below names the text it replaces, and the test fails if that text is
no longer in the document (so the list cannot silently go stale). Everything else
runs exactly as written.
"""

import os
import pathlib
import re
import subprocess
import sys

import pytest


ROOT = pathlib.Path(__file__).resolve().parents[1]

# document -> [(text as written, text run)]: sizes only, never the API.
FAST = {
    "README.md": [
        ("k=40, EA=1e6, alpha=0.01, t1=2.0", "k=8, EA=1e6, alpha=0.01, t1=0.5"),
        ('method="exact", N=101, t1=70.0', 'method="exact", N=11, t1=5.0'),
        ("tandem_fishtail(t1=20000.0)", "tandem_fishtail(t1=200.0)"),
        ("np.linspace(0.005, 0.05, 64)", "np.linspace(0.005, 0.05, 4)"),
        ("string_pendulum(k=20, t1=1.0)", "string_pendulum(k=6, t1=0.2)"),
    ],
    "docs/guide.md": [
        (
            "angles, ts = (1.57, 1.18, 0.79, 0.39), jnp.linspace(0.0, 2.0, 101)",
            "angles, ts = (1.57, 1.18), jnp.linspace(0.0, 0.3, 11)",
        ),
        (
            "js.string_pendulum(k=16, EA=1e3, theta0=a, t1=2.0, **p)",
            "js.string_pendulum(k=4, EA=1e3, theta0=a, t1=0.3, **p)",
        ),
        (
            'formulation="displacement", k=40, EA=1e6, alpha=0.01)',
            'formulation="displacement", k=6, EA=1e6, alpha=0.01, t1=0.3)',
        ),
        (
            'formulation="displacement", k=40, EA=1e6, alpha=0.02)',
            'formulation="displacement", k=6, EA=1e6, alpha=0.02, t1=0.3)',
        ),
    ],
}


def python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.M | re.S)


# The guide's examples (identification, sweeps) repeat what test_fit, test_sweep and
# test_least_squares check, at a minute of compilation: slow.
@pytest.mark.parametrize(
    "document",
    ["README.md", pytest.param("docs/guide.md", marks=pytest.mark.slow)],
)
def test_code_blocks_run_in_order(document, tmp_path):
    text = (ROOT / document).read_text()
    for written, _ in FAST[document]:
        assert written in text, f"{document} no longer contains {written!r}"
    script = "\n\n".join(python_blocks(text))
    assert script, f"{document} has no python blocks"
    for written, run in FAST[document]:
        script = script.replace(written, run)
    env = dict(os.environ, MPLBACKEND="Agg", JAXSTRING_CACHE="off")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    out = subprocess.run(
        [sys.executable, "-c", script],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, (
        f"{document}:\n{out.stdout[-2000:]}\n{out.stderr[-4000:]}"
    )
