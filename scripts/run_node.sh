#!/usr/bin/env bash
# Start one mwip_ros node by hand with the project's parameter file, e.g. one per terminal:
#
#   scripts/run_node.sh disturbance_observer
#   scripts/run_node.sh dscndo_controller -p dscndo_controller:use_observer:=false
#   scripts/run_node.sh mcap_recorder -p output:=bags/my_run
#   scripts/run_node.sh plant_sim                      # start the plant last in lockstep
#
# Raw sensors (sensors.model: raw): MWIP_PARAMS="config/paper.yaml config/sensors_raw_realistic.yaml" (each file
# is a --params-file, in order) for every node, and `scripts/run_node.sh state_estimator` beside the others.
#
# Same as `ros2 run mwip_ros NODE --ros-args --params-file config/paper.yaml [ARGS]`.
# Every terminal uses ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-42} and localhost-only discovery, so they find
# each other and nobody else. MWIP_PARAMS=FILE picks another parameter file. In lockstep (the
# default) the recorder logs on /clock (use_sim_time); MWIP_MODE=realtime: on wall-clock time.
# The observer and the controller read no clock (their outputs carry the state's stamp; their clock
# follows the stamps they answer).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
NODES="plant_sim disturbance_observer dscndo_controller state_estimator mcap_recorder bag_replay robot_markers foxglove_server"
if [ $# -lt 1 ] || [ "$1" = -h ] || [ "$1" = --help ]; then
    awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; echo "nodes: $NODES"; exit 0
fi
NODE="$1"; shift
case " $NODES " in *" $NODE "*) ;; *) echo "run_node: unknown node '$NODE' (nodes: $NODES)" >&2; exit 2 ;; esac
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-42}"
bash "$ROOT/scripts/setup.sh" >&2
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
PARAMS="${MWIP_PARAMS:-$ROOT/config/paper.yaml}"
PF=(--params-file "$PARAMS")   # one --params-file per file of MWIP_PARAMS (several: space-separated, in order)
if [ ! -f "$PARAMS" ]; then
    PF=(); read -r -a FILES <<< "$PARAMS"
    for f in "${FILES[@]}"; do PF+=(--params-file "$f"); done
fi
EXTRA=()
if [ "${MWIP_MODE:-lockstep}" = lockstep ] && [ "$NODE" = mcap_recorder ]; then
    EXTRA=(-p use_sim_time:=true)
fi
echo "run_node: $NODE on ROS_DOMAIN_ID=$ROS_DOMAIN_ID with $PARAMS" >&2
exec "$NODE" --ros-args "${PF[@]}" "${EXTRA[@]}" "$@"
