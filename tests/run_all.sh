#!/usr/bin/env bash
# The test command: every tests/test_*.py in its own pytest process (with the whole
# suite in one process, XLA's CPU compiler once segfaulted late in the run; jax
# 0.10.2), JAXSTRING_TEST_JOBS of them at a time (default 2: most of a test's time is
# single-threaded XLA compilation, so two files share a 2-core machine well).
# Longest files first, so the two lanes finish together; files that may skip whole
# (an optional peer not installed) before them, so the last output printed is a
# file that ran. Each file's output is printed when it finishes, then one total line
# in pytest's format; the exit status is non-zero if any file failed.
# Extra arguments go to every pytest call (e.g. -m "not slow").
set -uo pipefail
cd "$(dirname "$0")/.."
t0=$(date +%s)
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
jobs="${JAXSTRING_TEST_JOBS:-2}"
logs="$(mktemp -d)"
trap 'rm -rf "$logs"' EXIT

# Measured durations on the 2-core CI machine, longest first; files not listed run last.
first="test_tether_moordyn test_physics test_fast_solvers test_tanker test_sweep test_tune_tanker test_fit
test_bdf test_tandem_line test_experiments_smoke test_solvers test_tether"
files=()
for name in $first; do [ -f "tests/$name.py" ] && files+=("tests/$name.py"); done
for f in tests/test_*.py; do
  case " ${files[*]} " in *" $f "*) ;; *) files+=("$f") ;; esac
done

run_one() {
  f="$1"; shift
  log="$logs/$(basename "$f").log"
  start=$(date +%s)
  python -m pytest -q -p no:cacheprovider --durations=3 "$@" "$f" >"$log" 2>&1
  rc=$?
  [ "$rc" -eq 5 ] && rc=0  # every test of the file deselected
  (
    flock 9
    echo "== $f: exit $rc, $(( $(date +%s) - start )) s"
    cat "$log"
  ) 9>"$logs/.lock"
  [ "$rc" -eq 0 ] || touch "$logs/FAILED_$(basename "$f")"
  return 0
}
export -f run_one
export logs

printf '%s\0' "${files[@]}" | xargs -0 -P "$jobs" -I{} bash -c 'run_one "$@"' _ {} "$@"

# One total over the files, from each file's pytest summary line ("3 passed, 1 skipped in 2.1s").
total=$(cat "$logs"/*.log | grep -E '^(=+ )?[0-9]+ [a-z]+.* in [0-9.]+s' |
  grep -oE '[0-9]+ (passed|failed|errors?|skipped|deselected|xfailed|xpassed|warnings?)' |
  awk '{sub(/s$/, "", $2); sub(/^error$/, "errors", $2); n[$2]+=$1}
       END {split("failed passed skipped deselected xfailed xpassed warning errors", o, " ");
            sep=""; for (i = 1; i <= 8; i++) if (o[i] in n) {printf "%s%d %s", sep, n[o[i]], o[i]; sep=", "}}')
echo "============ ${total:-no tests ran} in $(( $(date +%s) - t0 ))s ============"

failed=$(ls "$logs" | sed -n 's/^FAILED_//p')
if [ -n "$failed" ]; then
  echo "FAILED: $failed"
  exit 1
fi
echo "all test files passed"
