"""List the results that are older than the code they measure.

Run: ``python experiments/stale.py [--results DIR] [--only-bad]``.

Every file in experiments/results/ (.md, .csv, .png; not quick/) belongs to the
study of studies.py that writes it, and that study declares the source paths it
measures. One line per file, with its state:

* ``fresh``: the code fingerprint in the file's stamp (stamps.py: a hash of each
  measured module's syntax tree without docstrings, so edits to docstrings,
  comments or formatting do not count) equals the fingerprint of that code now;
* ``stale``: it differs. A stamp with a git commit but no fingerprint is judged
  by git history instead: the fingerprint of the measured code at that commit
  (read from git) against the code now; a commit git does not know is stale;
* ``unstamped``: the stamp has neither (written before stamps recorded them);
  the commit that last changed the file in git is shown for reference;
* ``unclaimed``: no study writes a file of that name.

Exit status 1 when any result is stale, unstamped or unclaimed, 0 otherwise.
"""

import argparse
import pathlib
import sys

import stamps
import studies


SUFFIXES = (".md", ".csv", ".png")


def _commit_of(path, root):
    """The commit that last changed `path` in git (short hash), or None."""
    out = stamps._git(["log", "-1", "--format=%h", "--", str(path)], root)
    return (out.strip() or None) if out else None


def check(results=studies.RESULTS, root=stamps.ROOT):
    """[(state, path, detail)] for every results file in `results` (see the module
    docstring for the states; a file that runs append to, with one stamp per run,
    is fresh when every run is)."""
    root = pathlib.Path(root)
    now, then = {}, {}

    def judge(study, stamp):
        code, commit = stamp.get("code"), stamp.get("commit")
        if code:
            if code == now[study.name]:
                return "fresh", f"{study.name}: code {code}"
            return "stale", f"{study.name}: code {code}, now {now[study.name]}"
        if commit and commit != "unknown":
            sha = commit.split("+")[0]
            if (study.name, sha) not in then:
                then[study.name, sha] = stamps.fingerprint(
                    study.paths, root, commit=sha
                )
            if then[study.name, sha] is None:
                return "stale", f"commit {sha[:10]} not in git history"
            if then[study.name, sha] == now[study.name]:
                return "fresh", f"{study.name}: code at commit {sha[:10]} unchanged"
            return "stale", f"{study.name}: code at commit {sha[:10]} changed since"
        return "unstamped", "no commit or code fingerprint in its stamp"

    out = []
    for path in sorted(pathlib.Path(results).iterdir()):
        if not path.is_file() or path.suffix not in SUFFIXES:
            continue
        study = studies.study_for(path.name)
        if study is None:
            out.append(("unclaimed", path, "no study in studies.py writes it"))
            continue
        if study.name not in now:
            now[study.name] = stamps.fingerprint(study.paths, root)
        judged = [judge(study, stamp) for stamp in stamps.read_stamps(path)]
        judged = judged or [judge(study, {})]
        for state in ("stale", "unstamped", "fresh"):
            if any(s == state for s, _ in judged):
                detail = next(d for s, d in judged if s == state)
                break
        if state == "unstamped":
            last = _commit_of(path, root)
            if last:
                detail += f"; last committed in {last}"
        out.append((state, path, detail))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", default=str(studies.RESULTS), help="results folder")
    p.add_argument(
        "--only-bad", action="store_true", help="print stale, unstamped, unclaimed"
    )
    a = p.parse_args(argv)
    rows = check(a.results)
    counts = {}
    for state, path, detail in rows:
        counts[state] = counts.get(state, 0) + 1
        if state != "fresh" or not a.only_bad:
            print(f"{state:9s}  {path.name}  ({detail})")
    print(", ".join(f"{n} {s}" for s, n in sorted(counts.items())) or "no results")
    return int(any(state != "fresh" for state, _, _ in rows))


if __name__ == "__main__":
    sys.exit(main())
