#!/usr/bin/env bash
# Create/refresh the project venv (.venv) with the pinned dependencies and an
# editable install of mwip_ros. Idempotent: skips work when nothing changed.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
STAMP="$VENV/.mwip_setup_stamp"
# pip >= 25.3 always does PEP 660 editable installs; older pip may fall back to
# `setup.py develop`, which honours setup.cfg's [develop] script_dir and would
# put the console scripts in .venv/lib/mwip_ros instead of .venv/bin.
PIP_VERSION="26.3"
CONSOLE_SCRIPTS=(plant_sim disturbance_observer dscndo_controller mcap_recorder
                 bag_replay mwip_sim mwip_theorem mwip_report mwip_bag_repair mwip_sweep mwip_tune
                 robot_markers foxglove_server mwip_ctl state_estimator mwip_identify mwip_moteus_emulator
                 mwip_robot robot_state wheel_driver)

cd "$ROOT"

pick_python() {
    local cand
    for cand in python3.11 python3; do
        if command -v "$cand" >/dev/null 2>&1 &&
           "$cand" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' 2>/dev/null; then
            echo "$cand"
            return 0
        fi
    done
    return 1
}

if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import sys' >/dev/null 2>&1; then
    PY="$(pick_python)" || { echo "setup: need python3.11 (or python3 >= 3.11) on PATH" >&2; exit 1; }
    echo "setup: creating .venv with $PY ($("$PY" --version 2>&1))"
    rm -rf "$VENV"
    "$PY" -m venv "$VENV"
fi

hash_inputs() {
    "$VENV/bin/python" - requirements.txt setup.py setup.cfg package.xml scripts/setup.sh <<'PY'
import hashlib, sys
h = hashlib.sha256()
for name in sys.argv[1:]:
    with open(name, 'rb') as f:
        h.update(name.encode() + b'\0' + f.read() + b'\0')
print(h.hexdigest())
PY
}
WANT="$(hash_inputs)"

if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$WANT" ]; then
    echo "setup: .venv up to date"
    exit 0
fi

rm -f "$STAMP"
LOG="$VENV/.mwip_setup.log"
: > "$LOG"

# pip's own output (warnings included) goes to $LOG; shown only on failure.
pip_install() {
    if ! "$VENV/bin/python" -m pip --disable-pip-version-check install "$@" >>"$LOG" 2>&1; then
        echo "setup: pip install $* failed; last lines of $LOG:" >&2
        tail -n 40 "$LOG" >&2
        exit 1
    fi
}

echo "setup: installing pip==$PIP_VERSION"
pip_install "pip==$PIP_VERSION"

echo "setup: installing requirements.txt (log: .venv/.mwip_setup.log)"
pip_install -r requirements.txt

echo "setup: installing mwip_ros (editable)"
pip_install --no-deps -e .

missing=()
for s in "${CONSOLE_SCRIPTS[@]}"; do
    [ -x "$VENV/bin/$s" ] || missing+=("$s")
done
if [ "${#missing[@]}" -gt 0 ]; then
    echo "setup: console scripts missing from .venv/bin: ${missing[*]}" >&2
    exit 1
fi

# numba compiles each law's batch loop the first time a sweep runs it (15 to 40 s a loop on 2 cores): compile them
# now, while set-up is waited for anyway, so the first sweep of a fresh clone runs at the speed of the next
# (mwip_ros/sweep/warm.py; cached under mwip_ros/ until the code changes). A failure only warns: a sweep compiles
# what is missing at its start, and says so.
# MWIP_SETUP_WARM=0: the caller compiles them itself (scripts/test.sh, at the idle scheduling class beside its
# timed tests).
if [ "${MWIP_SETUP_WARM:-1}" = "0" ]; then
    echo "setup: the batch loops are not compiled here (MWIP_SETUP_WARM=0: the caller compiles them)"
else
    "$VENV/bin/python" -m mwip_ros.sweep.warm || echo "setup: warning: the batch loop was not compiled ahead" >&2
fi

echo "$WANT" > "$STAMP"
echo "setup: done"
