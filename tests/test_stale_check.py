"""The stale check of experiments/results (experiments/stale.py): the code
fingerprint ignores docstrings, comments and formatting but not code, and the
checker calls a result without a stamp "unstamped", one stamped with the code as
it is "fresh" and one stamped with other code "stale"."""

import stale
import stamps
import studies


def _fingerprint(tmp_path, source):
    (tmp_path / "pkg").mkdir(exist_ok=True)
    (tmp_path / "pkg" / "mod.py").write_text(source)
    return stamps.fingerprint(["pkg"], root=tmp_path)


MODULE = '''"""A module."""


def f(x):
    """Twice x."""
    return 2 * x  # doubled
'''


def test_docstring_and_comment_edits_keep_the_fingerprint(tmp_path):
    before = _fingerprint(tmp_path, MODULE)
    assert len(before) == 16
    edited = MODULE.replace("A module.", "A module, documented at length.")
    edited = edited.replace('"""Twice x."""', '"""Twice x,\n    on two lines."""')
    edited = edited.replace("# doubled", "# times two").replace("2 * x", "2*x")
    assert _fingerprint(tmp_path, edited) == before


def test_code_edits_change_the_fingerprint(tmp_path):
    before = _fingerprint(tmp_path, MODULE)
    assert _fingerprint(tmp_path, MODULE.replace("2 * x", "3 * x")) != before
    # a module that is only a docstring is code that does nothing, not missing
    assert _fingerprint(tmp_path, '"""Only a docstring."""\n') != before
    (tmp_path / "pkg" / "extra.py").write_text("y = 1\n")
    assert _fingerprint(tmp_path, MODULE) != before


def test_checker_states(tmp_path, capsys):
    study = studies.BY_NAME["step_cost"]
    line = stamps.format_stamp(stamps.stamp_fields(study.paths))
    fields = stamps.parse_stamp(line)
    assert fields["code"] == stamps.fingerprint(study.paths)
    (tmp_path / "step_cost.md").write_text("## Step cost\n\n| k |\n|---|\n| 40 |\n")
    (tmp_path / "step_cost.csv").write_text(f"# {line}\nk\n40\n")
    other = line.replace(fields["code"], "0" * 16)
    (tmp_path / "step_cost_quick.md").write_text(f"## Step cost\n\n_{other}_\n")
    (tmp_path / "no_such_study.md").write_text("## ?\n")
    states = {p.name: state for state, p, _ in stale.check(tmp_path)}
    assert states == {
        "step_cost.md": "unstamped",
        "step_cost.csv": "fresh",
        "step_cost_quick.md": "stale",
        "no_such_study.md": "unclaimed",
    }
    assert stale.main(["--results", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "unstamped  step_cost.md" in out
    for name in ("step_cost_quick.md", "no_such_study.md"):
        (tmp_path / name).unlink()
    (tmp_path / "step_cost.md").write_text(f"## Step cost\n\n_{line}_\n")
    assert stale.main(["--results", str(tmp_path)]) == 0


def test_git_fallback_reads_the_code_at_a_commit():
    study = studies.BY_NAME["step_cost"]
    at_head = stamps.fingerprint(study.paths, commit="HEAD")
    assert at_head is not None and len(at_head) == 16
    assert stamps.fingerprint(study.paths, commit="0" * 40) is None


def test_the_writer_stamps_every_file(tmp_path, monkeypatch):
    import harness

    monkeypatch.setenv("JAXSTRING_RESULTS_DIR", str(tmp_path))
    harness.write_table("step_cost", [{"k": 40}], ["k"], "Step cost")
    fig, _ = harness.new_figure()
    harness.savefig(fig, "step_cost")
    harness.write_text("step_cost_steps.csv", "k\n40\n")
    code = stamps.fingerprint(studies.BY_NAME["step_cost"].paths)
    for name in ("step_cost.md", "step_cost.csv", "step_cost.png"):
        fields = stamps.read_stamp(tmp_path / name)
        assert fields["code"] == code and fields["commit"], name
        assert fields["date"].endswith("Z") and fields["command"].startswith("python")
    assert stamps.read_stamp(tmp_path / "step_cost_steps.csv")["code"] == code
    assert {state for state, _, _ in stale.check(tmp_path)} == {"fresh"}
