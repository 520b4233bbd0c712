#!/usr/bin/env bash
# Set up .venv (if needed) and run the test suite: every tier (CI). Extra args go to pytest, e.g.
# `scripts/test.sh -m unit -n 2` (the fast loop, two workers), `-m "unit or graph"`, `-m e2e`; the tiers: test/conftest.py.
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

# One line per test file with its share of the suite done, so a long run shows where it is.
echo "test: python -m pytest ${targets[*]} $*"
rc=0
python -m pytest "${targets[@]}" "$@" || rc=$?
if [ "$rc" -eq 5 ]; then
    echo "test: pytest collected no tests; treating as failure" >&2
    exit 1
fi
exit "$rc"
