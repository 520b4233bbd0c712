#!/usr/bin/env bash
# The main job: run the ROS graph for DSC and then DSCNDO, record both runs, write the report.
#
#   scripts/run_experiment.sh [--params FILE]... [--mode lockstep|realtime] [--duration S] [--no-record]
#                             [--out DIR] [--laws dsc,dscndo,lqr,lqr_ndo]
#
# --params may be repeated: a base file, then overlays (config/sensing_realistic.yaml, a tuned
# overlay), merged in order as ROS merges repeated --params-file.
# --laws picks the runs (default dsc,dscndo): dsc and dscndo are DSC without and with the
# observer term, lqr and lqr_ndo the LQR baseline without and with it.
#
# Bags, logs and the report go to DIR (default: bags/), named by date and controller.
# Each node is its own process (plant_sim, disturbance_observer, dscndo_controller,
# mcap_recorder), on a private ROS domain with localhost-only discovery. Every process
# started here is stopped by PID when the run ends, fails, or is interrupted (Ctrl-C).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PARAMS=()   # --params may be given several times: a base file, then overlays (merged in order, as ROS does)
MODE=lockstep
DURATION=""
RECORD=1
OUT="$ROOT/bags"
LAWS="dsc,dscndo"

usage() { awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; }
while [ $# -gt 0 ]; do
    case "$1" in
        --params) [ -f "$2" ] || { echo "run_experiment: no such parameter file: $2" >&2; exit 2; }
                  PARAMS+=("$(cd "$(dirname "$2")" && pwd)/$(basename "$2")"); shift 2 ;;
        --mode) MODE="$2"; shift 2 ;;
        --duration) DURATION="$2"; shift 2 ;;
        --no-record) RECORD=0; shift ;;
        --out) mkdir -p "$2"; OUT="$(cd "$2" && pwd)"; shift 2 ;;
        --laws) LAWS="$2"; shift 2 ;;
        -h|--help) usage; exit 0 ;;
        *) echo "run_experiment: unknown argument '$1'" >&2; usage >&2; exit 2 ;;
    esac
done
case "$MODE" in lockstep|realtime) ;; *) echo "run_experiment: --mode must be lockstep or realtime" >&2; exit 2 ;; esac
if [ -n "$DURATION" ]; then
    [[ "$DURATION" =~ ^[0-9]+([.][0-9]*)?$ ]] || { echo "run_experiment: --duration must be seconds >= 0, got '$DURATION'" >&2; exit 2; }
    [[ "$DURATION" == *.* ]] || DURATION="$DURATION.0"   # ROS 2 reads 60 as an integer
fi
[ ${#PARAMS[@]} -gt 0 ] || PARAMS=("$ROOT/config/paper.yaml")
PF=()   # --params-file FILE for each
for f in "${PARAMS[@]}"; do PF+=(--params-file "$f"); done
IFS=',' read -r -a LAW_LIST <<< "$LAWS"
for CTRL in "${LAW_LIST[@]}"; do
    case "$CTRL" in dsc|dscndo|lqr|lqr_ndo) ;; *) echo "run_experiment: --laws takes dsc, dscndo, lqr, lqr_ndo; got '$CTRL'" >&2; exit 2 ;; esac
done

bash "$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
cd "$ROOT"

PIDS=()
TAIL=""
stop_all() {
    local pid
    if [ -n "$TAIL" ]; then kill -TERM "$TAIL" 2>/dev/null || true; wait "$TAIL" 2>/dev/null || true; TAIL=""; fi
    for pid in "${PIDS[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
    for pid in "${PIDS[@]}"; do
        for _ in $(seq 1 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
        if kill -0 "$pid" 2>/dev/null; then
            echo "run_experiment: pid $pid did not stop on SIGINT; killing it" >&2
            kill -KILL "$pid" 2>/dev/null || true
        fi
        wait "$pid" 2>/dev/null || true
    done
    PIDS=()
}
trap 'stop_all' EXIT
trap 'echo; echo "run_experiment: interrupted, stopping every node" >&2; exit 130' INT TERM

mwip_theorem --params "${PARAMS[@]}" || echo "run_experiment: warning: the gains break Theorem 2 (see above)" >&2

STAMP="$(date +%Y-%m-%d_%H%M%S)"
LOGS="$OUT/${STAMP}_logs"
mkdir -p "$LOGS"
# Lockstep: the recorder logs in sim time (the plant publishes /clock). The observer and the
# controller never read a clock (each output carries the stamp of the state it answers), so
# they run without use_sim_time: that spares each a /clock message per step (BENCHMARKS.md).
# Every -p names its node (-p NODE:name:=value): in ROS 2 a node's own section of a parameter file
# wins over a -p rule without a node name (README: The parameter file).
SIMTIME=()
[ "$MODE" = lockstep ] && SIMTIME=(-p mcap_recorder:use_sim_time:=true)
PLANT_EXTRA=(-p "plant_sim:mode:=$MODE")
[ -n "$DURATION" ] && PLANT_EXTRA+=(-p "plant_sim:duration_s:=$DURATION")

RUNS=()
ESTIMATES=()   # the observer's estimates (CSV), for a report from the plant's CSVs (--no-record)
for CTRL in "${LAW_LIST[@]}"; do
    export ROS_DOMAIN_ID=$(( (RANDOM % 200) + 1 ))
    USE_OBS=false; case "$CTRL" in dscndo|lqr_ndo) USE_OBS=true ;; esac
    LAW=dsc; case "$CTRL" in lqr|lqr_ndo) LAW=lqr ;; esac
    echo "=== $CTRL: $MODE run, ROS_DOMAIN_ID=$ROS_DOMAIN_ID, logs in ${LOGS#$ROOT/}/ ==="
    SUBS=2
    if [ "$RECORD" = 1 ]; then
        BAG="$OUT/${STAMP}_${CTRL}"
        mcap_recorder --ros-args "${PF[@]}" -p "mcap_recorder:output:=$BAG" "${SIMTIME[@]}" \
            > "$LOGS/${CTRL}_mcap_recorder.log" 2>&1 &
        PIDS+=($!)
        SUBS=3
        RUNS+=("$BAG")
    else
        RUNS+=("$LOGS/${CTRL}.csv")
    fi
    ESTIMATES+=("$LOGS/${CTRL}_estimates.csv")
    disturbance_observer --ros-args "${PF[@]}" -p "disturbance_observer:mode:=$MODE" -p "disturbance_observer:csv:=$LOGS/${CTRL}_estimates.csv" \
        > "$LOGS/${CTRL}_disturbance_observer.log" 2>&1 &
    PIDS+=($!)
    dscndo_controller --ros-args "${PF[@]}" -p "dscndo_controller:mode:=$MODE" -p "dscndo_controller:use_observer:=$USE_OBS" -p "dscndo_controller:law:=$LAW" \
        > "$LOGS/${CTRL}_dscndo_controller.log" 2>&1 &
    PIDS+=($!)
    plant_sim --ros-args "${PF[@]}" "${PLANT_EXTRA[@]}" -p "plant_sim:expected_subscribers:=$SUBS" \
        -p "plant_sim:csv:=$LOGS/${CTRL}.csv" > "$LOGS/${CTRL}_plant_sim.log" 2>&1 &
    PLANT=$!
    PIDS+=("$PLANT")
    tail --pid="$PLANT" -n +1 -f "$LOGS/${CTRL}_plant_sim.log" &   # show the plant's progress live
    TAIL=$!
    code=0
    wait "$PLANT" || code=$?
    wait "$TAIL" 2>/dev/null || true   # tail --pid ends by itself within a second of the plant
    TAIL=""
    stop_all
    case "$code" in
        0) ;;
        3) echo "run_experiment: the robot FELL in the $CTRL run (report still written)" >&2 ;;
        130|143) echo "run_experiment: interrupted, stopping every node" >&2; exit 130 ;;
        *) echo "run_experiment: plant_sim failed in the $CTRL run (exit $code); see ${LOGS#$ROOT/}/" >&2
           exit 1 ;;
    esac
    if [ "$RECORD" = 1 ]; then
        tail -n 1 "$LOGS/${CTRL}_mcap_recorder.log"
    fi
done

REPORT="$OUT/${STAMP}_report"
echo "=== report ==="
if [ "$RECORD" = 1 ]; then
    mwip_report "${RUNS[@]}" --labels "${LAW_LIST[@]}" --out "$REPORT"
else
    mwip_report "${RUNS[@]}" --estimates "${ESTIMATES[@]}" --labels "${LAW_LIST[@]}" --out "$REPORT"
fi
echo
if [ "$RECORD" = 1 ]; then
    echo "bags:  " "${RUNS[@]#$ROOT/}"
fi
echo "report: ${REPORT#$ROOT/}/metrics.md (figures fig3.png, observer.png; animation.gif)"
echo "logs:   ${LOGS#$ROOT/}/"
