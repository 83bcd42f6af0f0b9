"""Stamps of results files: when, on what machine, from which code, by which command.

Every file the experiments write under ``experiments/results/`` carries one stamp
line, ``key: value`` pairs separated by ``", "``::

    date: 2026-01-31T12:00:00Z, machine: AMD EPYC 7B13, cores: 2,
    load: 3.10 2.90 2.00, commit: 0123abc...+dirty, code: 5f0c1d2e3a4b5c6d,
    command: python experiments/step_cost.py, python: 3.11.7, jax: 0.10.2, ...

(one line in the file): in a ``.md`` file the italic line under the title, in a
``.csv`` file a ``# `` comment line at the top, in a ``.png`` file the text chunk
``Stamp``. ``date`` is UTC; ``commit`` is the checkout's git commit, ``+dirty``
when the working tree had changes; ``code`` is the fingerprint of the sources the
study measures (``studies.py`` declares them), so that ``stale.py`` can tell
whether a result still describes the code.

The fingerprint ignores what cannot change a measurement: for each Python module
it hashes ``ast.dump`` of the parsed module with the docstrings removed (comments
and formatting never reach the AST); other files (data, JSON) by their bytes.

Standard library only (``stale.py`` and the tests import it without JAX).
"""

import ast
import datetime
import functools
import hashlib
import os
import pathlib
import platform
import re
import struct
import subprocess
import sys
import zlib


ROOT = pathlib.Path(__file__).resolve().parents[1]

# The order of the keys in a stamp line.
KEYS = (
    "date",
    "machine",
    "cores",
    "load",
    "commit",
    "code",
    "command",
    "python",
    "jax",
    "numpy",
    "blas_threads",
    "xla_flags",
)


# ---------------------------------------------------------------------------
# Fingerprint of source code


def _strip_docstrings(tree):
    """Remove the docstring (a leading string expression) of the module and of
    every class and function in `tree`, in place."""
    for node in ast.walk(tree):
        if isinstance(
            node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
        ):
            body = node.body
            if (
                body
                and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)
            ):
                # keep the body non-empty (a function that is only a docstring)
                node.body = body[1:] or [ast.Pass()]
    return tree


@functools.lru_cache(maxsize=4096)
def source_fingerprint(data: bytes, name: str) -> str:
    """Hash of one file's content: for a Python module, of its syntax tree without
    docstrings (comments, blank lines and formatting do not count); for any other
    file, or a module that does not parse, of its bytes. Kept per content: the
    studies share most of their files."""
    if name.endswith(".py"):
        try:
            tree = _strip_docstrings(ast.parse(data, filename=name))
        except (SyntaxError, ValueError):
            pass
        else:
            text = ast.dump(tree, annotate_fields=True, include_attributes=False)
            return hashlib.sha256(text.encode()).hexdigest()
    return hashlib.sha256(data).hexdigest()


def _git(args, root=ROOT, binary=False):
    """Output of `git args` in `root` (None where git or the repository is missing
    or the command fails)."""
    try:
        out = subprocess.run(
            ["git", *args], cwd=root, capture_output=True, check=True, timeout=60
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    return out if binary else out.decode()


def _skip(rel: str) -> bool:
    parts = rel.split("/")
    return "__pycache__" in parts or rel.endswith((".pyc", ".nbi", ".nbc"))


def _files_now(path: str, root: pathlib.Path) -> list:
    """The files under `path` (a file or a folder, relative to `root`) in the
    working tree: tracked and untracked ones that git does not ignore (outside a
    git checkout: every file), caches left out."""
    out = _git(["ls-files", "-co", "--exclude-standard", "--", path], root)
    if out is None:
        full = root / path
        if full.is_file():
            names = [path]
        else:
            names = [
                str(p.relative_to(root)).replace(os.sep, "/")
                for p in full.rglob("*")
                if p.is_file()
            ]
    else:
        names = out.splitlines()
    return sorted(n for n in names if not _skip(n) and (root / n).is_file())


def _files_at(path: str, commit: str, root: pathlib.Path):
    out = _git(["ls-tree", "-r", "--name-only", commit, "--", path], root)
    return None if out is None else sorted(n for n in out.splitlines() if not _skip(n))


def fingerprint(paths, root=ROOT, commit=None):
    """Fingerprint (16 hex digits) of the code under `paths` (files or folders,
    relative to the repository root `root`): in the working tree, or at git
    `commit` (None where that commit cannot be read). Docstrings, comments and
    formatting do not change it; a path with no files counts as missing."""
    root = pathlib.Path(root)
    h = hashlib.sha256()
    for path in sorted(dict.fromkeys(str(p).rstrip("/") for p in paths)):
        if commit is None:
            names = _files_now(path, root)
            read = lambda n: (root / n).read_bytes()
        else:
            names = _files_at(path, commit, root)
            if names is None:
                return None
            read = lambda n: _git(["show", f"{commit}:{n}"], root, binary=True)
        h.update(f"{path}\n".encode())
        if not names:
            h.update(b"missing\n")
        for name in names:
            data = read(name)
            if data is None:
                return None
            h.update(f"{name}\n{source_fingerprint(data, name)}\n".encode())
    return h.hexdigest()[:16]


# ---------------------------------------------------------------------------
# Writing a stamp


def git_commit(root=ROOT) -> str:
    """The checkout's commit, with ``+dirty`` when tracked files have changes
    ("unknown" outside a git checkout)."""
    head = _git(["rev-parse", "HEAD"], root)
    if head is None:
        return "unknown"
    dirty = _git(["status", "--porcelain", "--untracked-files=no"], root)
    return head.strip() + ("+dirty" if dirty else "")


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def command_line() -> str:
    """The command that runs this process (`python experiments/X.py ...`)."""
    script = sys.argv[0] if sys.argv and sys.argv[0] else "python"
    try:
        script = os.path.relpath(script, ROOT)
    except ValueError:
        pass
    return "python " + " ".join([script] + sys.argv[1:])


def _version(package: str) -> str:
    try:
        from importlib.metadata import version

        return version(package)
    except Exception:  # noqa: BLE001  (not installed)
        return "-"


def stamp_fields(measures=None, root=ROOT, *, code=None, commit=None) -> dict:
    """The stamp of a results file written now, as a dict in `KEYS` order;
    `measures`: the source paths the study measures (no ``code`` without);
    `code`, `commit`: their values where already known (computed otherwise)."""
    fields = {
        "date": datetime.datetime.now(datetime.timezone.utc).strftime(
            "%Y-%m-%dT%H:%M:%SZ"
        ),
        "machine": cpu_model(),
        "cores": os.cpu_count(),
        "load": " ".join(f"{x:.2f}" for x in os.getloadavg()),
        "commit": commit or git_commit(root),
        "code": code or (fingerprint(measures, root) if measures else None),
        "command": command_line(),
        "python": platform.python_version(),
        "jax": _version("jax"),
        "numpy": _version("numpy"),
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "?"),
        "xla_flags": os.environ.get("XLA_FLAGS", "") or "-",
    }
    return {k: v for k, v in fields.items() if v is not None}


def format_stamp(fields: dict) -> str:
    return ", ".join(f"{k}: {v}" for k, v in fields.items())


# ---------------------------------------------------------------------------
# Reading a stamp


_SPLIT = re.compile(r", (?=[a-z_0-9]+: )")


def parse_stamp(line: str) -> dict:
    """The fields of a stamp line (`format_stamp`'s, or the older one with
    ``date``, ``command``, ``processor`` ...); {} where the line is no stamp."""
    line = line.strip().lstrip("#").strip().strip("_").strip()
    line = line.removeprefix("run: ")  # one run of a file that runs append to
    if not line.startswith("date: "):
        return {}
    out = {}
    for part in _SPLIT.split(line):
        key, sep, value = part.partition(": ")
        if sep:
            out[key.strip()] = value.strip().strip("`")
    return out


def png_text(path) -> dict:
    """The text chunks (tEXt, zTXt, iTXt) of a PNG file."""
    out = {}
    with open(path, "rb") as f:
        if f.read(8) != b"\x89PNG\r\n\x1a\n":
            return out
        while True:
            head = f.read(8)
            if len(head) < 8:
                break
            length, kind = struct.unpack(">I4s", head)
            data = f.read(length)
            f.read(4)  # CRC
            if kind == b"tEXt":
                key, _, value = data.partition(b"\0")
                out[key.decode("latin-1")] = value.decode("latin-1")
            elif kind == b"zTXt":
                key, _, rest = data.partition(b"\0")
                out[key.decode("latin-1")] = zlib.decompress(rest[1:]).decode("latin-1")
            elif kind == b"iTXt":
                key, _, rest = data.partition(b"\0")
                compressed, rest = rest[0], rest[2:]
                _, _, rest = rest.partition(b"\0")  # language tag
                _, _, text = rest.partition(b"\0")  # translated keyword
                text = zlib.decompress(text) if compressed else text
                out[key.decode("latin-1")] = text.decode("utf-8")
            elif kind == b"IEND":
                break
    return out


def _chunk(kind: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(kind + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def set_png_text(path, key: str, text: str) -> None:
    """Write the text chunk `key` (tEXt, Latin-1) into the PNG file at `path`,
    replacing any chunk of that key."""
    data = pathlib.Path(path).read_bytes()
    out, pos = [data[:8]], 8
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        end = pos + 12 + length
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"IEND":
            value = text.encode("latin-1", errors="replace")
            out.append(_chunk(b"tEXt", key.encode("latin-1") + b"\0" + value))
        if not (kind in (b"tEXt", b"iTXt", b"zTXt") and body.startswith(
                key.encode("latin-1") + b"\0")):  # fmt: skip
            out.append(data[pos:end])
        pos = end
    pathlib.Path(path).write_bytes(b"".join(out))


def read_stamps(path) -> list:
    """Every stamp of a results file (.md, .csv, .png) as dicts: the one in its
    first lines, and in a CSV that runs append to, each run's ``# run: `` line."""
    path = pathlib.Path(path)
    if path.suffix == ".png":
        fields = parse_stamp(png_text(path).get("Stamp", ""))
        return [fields] if fields else []
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            lines = f.readlines()
    except OSError:
        return []
    out = []
    for i, line in enumerate(lines):
        if i < 12 or (path.suffix == ".csv" and line.startswith("# run: ")):
            fields = parse_stamp(line)
            if fields:
                out.append(fields)
    return out


def read_stamp(path) -> dict:
    """The (first) stamp of a results file as a dict ({} if none)."""
    found = read_stamps(path)
    return found[0] if found else {}
