#!/usr/bin/env bash
# Set up .venv (if needed) and run the test suite: every tier (CI). Extra args go to pytest, e.g.
# `scripts/test.sh -m unit` (the fast loop), `-m "unit or node" -n 2`, `-m graph`, `test/core/closed_loop/test_sim.py`;
# the tiers: test/conftest.py.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

# The session's own ROS domain (yours if ROS_DOMAIN_ID is set), locked while the tests run; every
# graph a test starts takes a free domain of its own.
# shellcheck disable=SC1091
source "$ROOT/scripts/domain.sh"
mwip_domain test || exit $?

# Run test/ unless the caller named test paths of their own.
targets=(test/)
for a in "$@"; do
    case "$a" in
        -*) ;;
        *) if [ -e "${a%%::*}" ]; then targets=(); break; fi ;;
    esac
done

# Without -m, -n or test paths of the caller's: three runs, so that every core works and nothing timed shares it
# with work of its own class. The tests marked alone (they keep real-time deadlines or time something on the wall
# clock) and the bench run one at a time, with the tiers that start no ROS process (unit, cli, node, slow,
# montecarlo: test/conftest.py) on every core beside them at Linux's idle scheduling class (scripts/idle_priority.py):
# those take only the CPU the timed tests leave. Then the in-process run comes back from idle at nice 10 and the graph
# and e2e tests run on every core beside what is left of it (docs/development.md has the measurements).
# With -m, -n or paths of yours: one pytest run.
split=1
[ "${#targets[@]}" -eq 0 ] && split=0
for a in "$@"; do
    case "$a" in
        -m|-m?*|-n|-n?*|--numprocesses|--numprocesses=*) split=0 ;;
    esac
done

# The set-up (scripts/setup.sh). In the three runs, the batch loops it would compile ahead (mwip_ros/sweep/warm.py,
# about 370 s of CPU) are compiled in the background at the idle scheduling class before the in-process tiers,
# beside the timed tests, instead of before every test.
if [ "$split" -eq 1 ]; then
    MWIP_SETUP_WARM=0 bash "$ROOT/scripts/setup.sh"
else
    bash "$ROOT/scripts/setup.sh"
fi
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"

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
logs="$(mktemp -d "${TMPDIR:-/tmp}/mwip_test.XXXXXX")"
in_process_cmd=(python -m pytest "${targets[@]}" -m "(unit or cli or node or slow or montecarlo) and not alone" -n auto
                --dist worksteal "$@")
echo "test: python -m mwip_ros.sweep.warm, then ${in_process_cmd[*]} (at idle priority beside the tests marked" \
     "alone; their output at their end)"
python scripts/idle_priority.py run bash -c 'python -m mwip_ros.sweep.warm ||
    echo "test: warning: the batch loops were not compiled ahead (the tests compile what they need)" >&2
    exec "$@"' in_process "${in_process_cmd[@]}" > "$logs/in_process.log" 2>&1 &
in_pid=$!
trap 'kill -TERM "$in_pid" 2>/dev/null || true; rm -rf "$logs"' INT TERM EXIT   # (a background job ignores SIGINT)
# what keeps real-time deadlines or times the wall clock, and the bench: one at a time, beside only idle work
run_pytest "${targets[@]}" -m "alone or bench" --durations=10 "$@" || rc=$?
alone=$((SECONDS - start))
# the rest of the in-process run back from idle, at nice 10: the graph and e2e tests beside it come first (with both
# at nice 0 they took 543 s instead of 407 s, and a node test counting 1 s of Twists got 6 of 10)
python scripts/idle_priority.py restore "$in_pid" 10
# lockstep graphs and whole jobs wait on their processes' answers, not on a clock: two at a time beside the rest of
# the in-process run (each graph on a domain of its own; --dist loadfile keeps a module's tests, and the graph they
# share, on one worker. --dist loadgroup with only the modules that share a graph grouped took longer: 724 s against
# 582 s, docs/benchmarks-history.md)
run_pytest "${targets[@]}" -m "(graph or e2e) and not alone" -n auto --dist loadfile "$@" || rc=$?
shared=$((SECONDS - start - alone))
in_rc=0
wait "$in_pid" || in_rc=$?
trap - INT TERM EXIT
in_process=$((SECONDS - start))
echo "test: ${in_process_cmd[*]} (its output:)"
cat "$logs/in_process.log"
rm -rf "$logs"
if [ "$in_rc" -eq 5 ]; then
    echo "test: pytest collected no tests; treating as failure" >&2
    in_rc=1
fi
if [ "$in_rc" -ne 0 ]; then rc=$in_rc; fi
echo "test: ${alone} s alone (the in-process tiers beside them at idle priority), then the graph and e2e tests" \
     "${shared} s two at a time; the in-process tiers ended at ${in_process} s; in all $((SECONDS - start)) s"
exit "$rc"
