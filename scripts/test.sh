#!/usr/bin/env bash
# Set up .venv (if needed) and run the test suite: every tier (CI). Extra args go to pytest, e.g.
# `scripts/test.sh -m unit` (the fast loop), `-m "unit or node" -n 2`, `-m graph`, `test/core/test_sim.py`;
# the tiers: test/conftest.py.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

# The session's own ROS domain (yours if ROS_DOMAIN_ID is set), locked while the tests run; every
# graph a test starts takes a free domain of its own.
# shellcheck disable=SC1091
source "$ROOT/scripts/domain.sh"
mwip_domain test || exit $?
bash "$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"

# Run test/ unless the caller named test paths of their own.
targets=(test/)
for a in "$@"; do
    case "$a" in
        -*) ;;
        *) if [ -e "${a%%::*}" ]; then targets=(); break; fi ;;
    esac
done

# The linter first (ruff.toml): a finding fails the run before any test starts.
echo "test: python -m ruff check ."
if python -m ruff check .; then
    echo "test: ruff: clean"
else
    echo "test: ruff found problems" >&2
    exit 1
fi
# Then the type checker (mypy.ini: core/, params/, msgs/; its cache .mypy_cache/): an error fails the run too.
echo "test: python -m mypy"
if python -m mypy; then
    echo "test: mypy: clean"
else
    echo "test: mypy found type errors (mypy.ini; run it alone: python -m mypy)" >&2
    exit 1
fi

# Without -m, -n or test paths of the caller's: three runs, so that every core works and nothing timed shares it.
# First the tiers that start no ROS process (unit, cli, node, slow, montecarlo: test/conftest.py) on every core
# (pytest-xdist), then the graph and e2e tests on every core, then those marked alone (they keep real-time
# deadlines, time the graph or hand a domain to a script) and the bench one test at a time. (The first run at the
# idle scheduling class beside the third was tried: shorter, but a test starved at that class misses what it times;
# docs/benchmarks-history.md.) With -m, -n or paths of yours: one pytest run.
split=1
[ "${#targets[@]}" -eq 0 ] && split=0
for a in "$@"; do
    case "$a" in
        -m|-m?*|-n|-n?*|--numprocesses|--numprocesses=*) split=0 ;;
    esac
done

run_pytest() {   # pytest's exit code; 5 (nothing collected) is a failure of the whole run
    local rc=0
    echo "test: python -m pytest $*"
    python -m pytest "$@" || rc=$?
    if [ "$rc" -eq 5 ]; then
        echo "test: pytest collected no tests; treating as failure" >&2
        rc=1
    fi
    return "$rc"
}

if [ "$split" -eq 0 ]; then
    run_pytest "${targets[@]}" "$@"
    exit $?
fi
start=$SECONDS
rc=0
run_pytest "${targets[@]}" -m "unit or cli or node or slow or montecarlo" -n auto --dist worksteal "$@" || rc=$?
in_process=$((SECONDS - start))
# lockstep graphs and whole jobs wait on their processes' answers, not on a clock: two at a time (each graph on a
# domain of its own; --dist loadfile keeps a module's tests, and the graph they share, on one worker. --dist
# loadgroup with only the modules that share a graph grouped took longer: 724 s against 582 s,
# docs/benchmarks-history.md)
run_pytest "${targets[@]}" -m "(graph or e2e) and not alone" -n auto --dist loadfile "$@" || rc=$?
shared=$((SECONDS - start - in_process))
# what keeps real-time deadlines or times the graph, and the bench: alone
run_pytest "${targets[@]}" -m "(graph or e2e) and alone or bench" --durations=10 "$@" || rc=$?
echo "test: in-process tiers ${in_process} s, process tests ${shared} s two at a time and" \
     "$((SECONDS - start - in_process - shared)) s alone, in all $((SECONDS - start)) s"
exit "$rc"
