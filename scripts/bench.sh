#!/usr/bin/env bash
# Benchmarks: the DDS floor, the lockstep graph, real time at 200 Hz and 1 kHz, the offline
# simulator and each node's peak memory, all measured in this one run on this machine.
#
#   scripts/bench.sh [--quick] [--repeat N] [--markdown FILE] [--keep DIR]
#
# Sets up .venv if needed. Prints one table (Markdown) on stdout, progress on stderr.
# --quick runs everything briefly (about a minute; the tests use it). A full run takes
# about 3 minutes. Numbers, not pass/fail: this is not part of the test suite.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
for a in "$@"; do
    case "$a" in -h|--help) exec "$ROOT/.venv/bin/python" "$ROOT/scripts/bench.py" --help 2>/dev/null \
        || { awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0; } ;;
    esac
done
# shellcheck disable=SC1091
source "$ROOT/scripts/domain.sh"
mwip_domain bench >&2 || exit $?   # the benchmark's graphs run on it (yours if set, else a free one)
bash "$ROOT/scripts/setup.sh" >&2
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
exec python "$ROOT/scripts/bench.py" "$@"
