#!/usr/bin/env bash
# Run every test file in its own Python process (the README's test command).
# One process per file keeps XLA's compiled state small: with the whole suite in
# one process, XLA's CPU compiler segfaulted (jax 0.10.2) late in the run, in
# tests that pass on their own.
export OPENBLAS_NUM_THREADS=1 MPLBACKEND=Agg
cd "$(dirname "$0")/.."
status=0
ran=0
for f in tests/test_*.py; do
  echo "== $f"
  python -m pytest -q -p no:cacheprovider --durations=5 "$f" "$@"
  rc=$?
  if [ "$rc" -eq 5 ]; then rc=0; else ran=1; fi
  if [ "$rc" -ne 0 ]; then status=$rc; echo "FAILED: $f (exit $rc)"; fi
done
if [ "$ran" -eq 0 ]; then echo "no tests collected" >&2; exit 1; fi
exit "$status"
