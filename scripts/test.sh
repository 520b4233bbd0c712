#!/usr/bin/env bash
# Set up .venv (if needed) and run the test suite. Extra args go to pytest.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

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

echo "test: python -m pytest -q ${targets[*]} $* (ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
rc=0
python -m pytest -q "${targets[@]}" "$@" || rc=$?
if [ "$rc" -eq 5 ]; then
    echo "test: pytest collected no tests; treating as failure" >&2
    exit 1
fi
exit "$rc"
