#!/usr/bin/env bash
# The main job: run the ROS graph for DSC and then DSCNDO (or the laws you pick), record each run, write the report.
#
#   scripts/run_experiment.sh [--params FILE [FILE ...]] [--mode lockstep|realtime] [--duration S]
#                             [--no-record] [--out DIR] [--name NAME] [--laws LAW[,LAW...]]
#                             [--sensors state|raw] [--robot-state]
#                             [--robot mock|upkie-pybullet|emulated-moteus] [--realtime-priority P]
#                             [--emulator-options "OPTIONS"]
#
# --params takes a base file, then overlays (config/sensing_realistic.yaml, a tuned overlay), merged
# in order as ROS merges repeated --params-file; every node's section is checked before anything starts.
# --laws picks the runs, one after the other: any registered law (mwip_sim --help lists them: dsc, dscndo,
# lqr, lqr_ndo, smc, smc_ndo, mpc, mpc_ndo, and plug-ins named in MWIP_ROS_LAWS); NAME_ndo (dscndo for dsc)
# is the law with the observer term. Without --laws: the files' law (dscndo_controller.law; config/paper.yaml's
# is dsc) without and with the observer term, so dsc,dscndo by default and smc,smc_ndo for a file with law: smc.
# With --laws, a law the files name other than dsc is replaced, and a note says so.
# --duration S: simulated seconds of each run, as mwip_sim --duration takes them (10, 2.5, 1e3): > 0 and at
# most 1e7 (default: the files' plant_sim.duration_s, 10 s in config/paper.yaml). 0 is refused, and so is a
# file's duration_s: 0 (until stopped): every run must end for the next law and the report.
# --sensors raw puts config/sensors_raw_realistic.yaml BEFORE the --params files (your files overlay it, so
# what they set wins, e.g. state_estimator method: complementary): the plant publishes what an IMU on the body
# and a motor encoder measure, and a state_estimator (started here, with the same files) turns them into
# joint_states. Files that set sensors.model: state contradict it (refused). A parameter file that sets
# sensors.model: raw itself starts the estimator too.
#
# --robot NAME runs the graph against a robot's own interface instead of plant_sim (docs/hardware.md): the
# wheel_driver node owns the robot's clock, reads its devices through a backend and writes the commands, and the
# state_estimator turns its raw IMU and encoders into joint_states. mock: commands mirrored into the wheels' torque
# states, nothing moves (checks the wiring; default files config/paper.yaml config/sensors_raw_realistic.yaml).
# upkie-pybullet: Upkie in its own PyBullet, headless, in lockstep or --mode realtime (default files
# config/paper.yaml config/upkie.yaml). emulated-moteus: the moteus emulator (mwip_moteus_emulator, its own process,
# started here: two controllers on a pty, the files' plant behind them held at its initial state until the driver
# first drives, its IMU at 400 Hz on imu/data_raw) and the
# driver with the moteus backend on that pty, always realtime (default files config/paper.yaml config/upkie.yaml:
# Upkie's rigid model). The driver starts enabled (require_enable false: nobody is there to enable a simulated
# robot). The report adds each run's period timing (the driver's summary), and the emulator's counters are in the
# logs. --realtime-priority P runs the loop's nodes and the driver under SCHED_FIFO P (realtime_priority; root or
# CAP_SYS_NICE), and the emulator under chrt -f P. --emulator-options "OPTIONS" (emulated-moteus) passes the
# emulator its own options, its faults on demand: "--latency 0.002 --loss 0.01", "--silent right --silent-at 20"
# (mwip_moteus_emulator --help).
#
# --robot-state also starts robot_state (odom, the URDF on robot_description, wheel_joint_states; docs/graph.md):
# the bags then hold odom, robot_description and wheel_joint_states too. Off by default: the bags stay as they were.
#
# Bags, logs and the report go to DIR (default: bags/) as NAME_<law>, NAME_logs and NAME_report, NAME
# being the date and time (or --name NAME); a second experiment with the same NAME (started in the
# same second) gets its own names with a suffix (NAME-2_...) instead of sharing or overwriting files.
# Each node is its own process (plant_sim, disturbance_observer, dscndo_controller, mcap_recorder, and
# state_estimator with raw sensors)
# with localhost-only discovery, on your ROS_DOMAIN_ID if set, else on a free domain in 1..101
# (printed first); two experiments never share one. Every process started here is stopped by PID when the run ends, fails, or is interrupted.
#
# Ctrl-C (or SIGTERM) during a run ends that run (every node stops as on its own end: the plant writes its summary,
# the recorder closes its bag), skips the laws not yet run, writes the report of the runs so far (the interrupted
# one up to where it stopped) and exits 130; a second Ctrl-C stops at once. Paths are printed relative to the
# directory you ran the command from (absolute when they are not under it).
#
# Exit codes: 0 every robot stayed up, 3 a robot fell (every run and the report are still done),
# 2 a usage or parameter mistake (nothing started), 1 a node failed, 130 interrupted (Ctrl-C; the report of the
# runs so far is written).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
CALLER="$(pwd -P)"   # where the user ran the command: paths are printed relative to it
shown() {   # a path as the user can use it from where they ran the command
    case "$1" in "$CALLER"/*) printf '%s' "${1#"$CALLER"/}" ;; *) printf '%s' "$1" ;; esac
}
PARAMS=()   # --params FILE [FILE ...]: a base file, then overlays (merged in order, as ROS merges repeated --params-file)
MODE=""   # --mode; default lockstep (realtime for --robot emulated-moteus)
DURATION=""
RECORD=1
OUT="$ROOT/bags"
LAWS=""    # --laws; empty: the files' law without and with the observer term (mwip_ros.cli.experiment)
NAME=""
SENSORS=state
ROBOT_STATE=0   # --robot-state: robot_state beside the loop
ROBOT=""        # --robot: a robot's side (wheel_driver) instead of plant_sim
PRIORITY=0      # --realtime-priority: SCHED_FIFO of the loop's nodes, the driver and the emulator
EMULATOR_OPTIONS=()   # --emulator-options: the emulator's own options (faults on demand)

usage() { awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; }
die() { echo "run_experiment: $*" >&2; exit 2; }
value_of() {   # $1 = option, then the rest of the command line: the option's value, or a usage error
    [ $# -ge 2 ] && [ -n "$2" ] && [[ "$2" != --* ]] || die "$1 needs a value (scripts/run_experiment.sh --help)"
    printf '%s' "$2"
}
while [ $# -gt 0 ]; do
    case "$1" in
        --params) shift
                  { [ $# -gt 0 ] && [[ "$1" != --* ]]; } || die "--params needs at least one FILE"
                  while [ $# -gt 0 ] && [[ "$1" != --* ]]; do
                      [ -f "$1" ] || die "--params: no such parameter file: $1"
                      PARAMS+=("$(cd "$(dirname "$1")" && pwd)/$(basename "$1")"); shift
                  done ;;
        --mode) MODE="$(value_of "$@")"; shift 2 ;;
        --duration) DURATION="$(value_of "$@")"; shift 2 ;;
        --no-record) RECORD=0; shift ;;
        --robot-state) ROBOT_STATE=1; shift ;;
        --robot) ROBOT="$(value_of "$@")"; shift 2
                 case "$ROBOT" in mock|upkie-pybullet|emulated-moteus) ;;
                     *) die "--robot must be mock, upkie-pybullet or emulated-moteus, got '$ROBOT'" ;; esac ;;
        --emulator-options) [ $# -ge 2 ] || die "--emulator-options needs a value (scripts/run_experiment.sh --help)"
                 read -r -a EMULATOR_OPTIONS <<< "$2"; shift 2 ;;
        --realtime-priority) PRIORITY="$(value_of "$@")"; shift 2
                 [[ "$PRIORITY" =~ ^[0-9]+$ ]] && [ "$PRIORITY" -le 99 ] || die "--realtime-priority takes 0..99, got '$PRIORITY'" ;;
        --out) OUT="$(value_of "$@")"; shift 2
               [ ! -e "$OUT" ] || [ -d "$OUT" ] || die "--out: $OUT exists and is not a directory" ;;
        --laws) LAWS="$(value_of "$@")"; shift 2 ;;
        --sensors) SENSORS="$(value_of "$@")"; shift 2 ;;
        --name) NAME="$(value_of "$@")"; shift 2
                [[ "$NAME" =~ ^[A-Za-z0-9][A-Za-z0-9._-]*$ ]] || die "--name takes letters, digits, '.', '_' and '-', got '$NAME'" ;;
        -h|--help) usage; exit 0 ;;
        *) echo "run_experiment: unknown argument '$1'" >&2; usage >&2; exit 2 ;;
    esac
done
case "$OUT" in /*) ;; *) OUT="$CALLER/$OUT" ;; esac   # a relative --out is where the user is, not the repository
[ -n "$MODE" ] || { [ "$ROBOT" = emulated-moteus ] && MODE=realtime || MODE=lockstep; }
case "$MODE" in lockstep|realtime) ;; *) die "--mode must be lockstep or realtime, got '$MODE'" ;; esac
if [ -n "$ROBOT" ]; then
    [ "$RECORD" = 1 ] || die "--robot needs the recording (the report reads the bag); drop --no-record"
    [ "$SENSORS" = state ] || die "--robot reads the robot's own IMU and encoders already; drop --sensors"
    [ ${#EMULATOR_OPTIONS[@]} -eq 0 ] || [ "$ROBOT" = emulated-moteus ] || die "--emulator-options is for --robot emulated-moteus"
    if [ ${#PARAMS[@]} -eq 0 ]; then   # each robot's files (the header above)
        case "$ROBOT" in
            mock) PARAMS=("$ROOT/config/paper.yaml" "$ROOT/config/sensors_raw_realistic.yaml") ;;
            *) PARAMS=("$ROOT/config/paper.yaml" "$ROOT/config/upkie.yaml") ;;
        esac
    fi
fi
case "$SENSORS" in state|raw) ;; *) die "--sensors must be state or raw, got '$SENSORS'" ;; esac
[ ${#PARAMS[@]} -gt 0 ] || PARAMS=("$ROOT/config/paper.yaml")
# the overlay first: the user's files are overlays on it, so every key they set wins (their estimator, noise)
[ "$SENSORS" = raw ] && PARAMS=("$ROOT/config/sensors_raw_realistic.yaml" "${PARAMS[@]}")
PF=()   # --params-file FILE for each
for f in "${PARAMS[@]}"; do PF+=(--params-file "$f"); done

# One ROS domain for the whole experiment, the user's if set, held (locked) until every node has stopped.
# shellcheck disable=SC1091
source "$ROOT/scripts/domain.sh"
mwip_domain run_experiment || exit $?

bash "$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "$ROOT/scripts/env.sh"
cd "$ROOT"

# The plan (mwip_ros/cli/experiment.py): --laws and --duration checked against the registry and the merged files,
# the laws to run (NAME FAMILY USE_OBSERVER), the plant's sensors.model (raw needs a state_estimator in the loop).
PLAN_ARGS=(--params "${PARAMS[@]}" --sensors "$SENSORS" --mode "$MODE")
[ -n "$ROBOT" ] && PLAN_ARGS+=(--robot "$ROBOT")
[ -n "$LAWS" ] && PLAN_ARGS+=(--laws "$LAWS")
[ -n "$DURATION" ] && PLAN_ARGS+=(--duration "$DURATION")
PLAN="$(python -m mwip_ros.cli.experiment "${PLAN_ARGS[@]}")" || exit 2
MODEL=state
BACKEND=""   # the wheel_driver's backend for --robot
LAW_LIST=(); FAMILY_OF=(); OBSERVER_OF=()
while read -r what a b c; do
    case "$what" in
        duration) DURATION="$a" ;;   # as Python writes a float (1000.0): ROS 2 reads it as a double, 60 as an integer
        model) MODEL="$a" ;;
        robot) BACKEND="$b" ;;
        run) LAW_LIST+=("$a"); FAMILY_OF+=("$b"); OBSERVER_OF+=("$c") ;;
    esac
done <<< "$PLAN"

# The parameter files, every node's section, checked before anything starts: a mistake is one line, exit 2.
theorem=0
mwip_theorem --params "${PARAMS[@]}" || theorem=$?
case "$theorem" in
    0) ;;
    1) echo "run_experiment: warning: the gains break Theorem 2 (see above); running anyway" >&2 ;;
    *) exit 2 ;;
esac

# Output names: date and time, made unique by creating the logs folder (mkdir is atomic): a second
# experiment started in the same second takes the next suffix instead of sharing or overwriting files.
mkdir -p "$OUT"
OUT="$(cd "$OUT" && pwd)"
BASE_STAMP="${NAME:-$(date +%Y-%m-%d_%H%M%S)}"
STAMP="$BASE_STAMP"
n=1
until mkdir "$OUT/${STAMP}_logs" 2>/dev/null; do
    n=$((n + 1))
    [ "$n" -le 1000 ] || die "cannot create a logs folder under $OUT"
    STAMP="${BASE_STAMP}-$n"
done
LOGS="$OUT/${STAMP}_logs"

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
INTERRUPTED=0
interrupted() {   # Ctrl-C or SIGTERM during the runs: end this run, then the report of the runs so far
    if [ "$INTERRUPTED" = 1 ]; then
        echo "run_experiment: interrupted again; stopping now, without the report" >&2
        exit 130
    fi
    INTERRUPTED=1
    echo
    echo "run_experiment: interrupted: ending this run (every node stops as at its end), then the report of the runs so far (Ctrl-C again: stop now)" >&2
    stop_all
}

# Lockstep: the recorder logs in sim time (the plant publishes /clock). The observer and the
# controller never read a clock (each output carries the stamp of the state it answers), so
# they run without use_sim_time: that spares each a /clock message per step
# (docs/benchmarks-history.md, "What the profiles showed, and what was done").
# Every -p names its node (-p NODE:name:=value): in ROS 2 a node's own section of a parameter file
# wins over a -p rule without a node name (docs/parameters.md).
SIMTIME=()
[ "$MODE" = lockstep ] && SIMTIME=(-p mcap_recorder:use_sim_time:=true)
PLANT_EXTRA=(-p "plant_sim:mode:=$MODE")
[ -n "$DURATION" ] && PLANT_EXTRA+=(-p "plant_sim:duration_s:=$DURATION")
SIDE=plant_sim   # the node that owns the robot's clock: plant_sim, or wheel_driver with --robot
DRIVER_EXTRA=()
if [ -n "$ROBOT" ]; then
    SIDE=wheel_driver
    DRIVER_EXTRA=(-p "wheel_driver:mode:=$MODE" -p "wheel_driver:backend:=$BACKEND" -p "wheel_driver:require_enable:=false")
    # a file's plant_sim duration_s is the robot's run too (the driver's own section may say otherwise)
    DRIVER_DURATION="${DURATION:-$(python -c "import sys; from mwip_ros import params as P; print(repr(float(P.merged_values(P.load_param_files(sys.argv[1:]))['duration_s'])))" "${PARAMS[@]}")}"
    DRIVER_EXTRA+=(-p "wheel_driver:duration_s:=$DRIVER_DURATION")
fi
PRIO=()   # --realtime-priority: each loop node's and the driver's realtime_priority
prio() { [ "$PRIORITY" = 0 ] || printf '%s\n' -p "$1:realtime_priority:=$PRIORITY"; }

RUNS=()
SUMMARIES=()   # --robot: each run's driver summary (its period timing)
RAN=()         # the laws whose run ended (or was interrupted): the report's
FELL=()        # the laws whose robot fell: the script then ends with exit 3, as plant_sim does
ESTIMATES=()   # the observer's estimates (CSV), for a report from the plant's CSVs (--no-record)
trap 'interrupted' INT TERM
for i in "${!LAW_LIST[@]}"; do
    [ "$INTERRUPTED" = 0 ] || break
    CTRL="${LAW_LIST[$i]}"; LAW="${FAMILY_OF[$i]}"; USE_OBS="${OBSERVER_OF[$i]}"
    echo "=== $CTRL: $MODE run, ROS_DOMAIN_ID=$ROS_DOMAIN_ID, logs in $(shown "$LOGS")/ ==="
    SUBS=2   # expected_subscribers as without an estimator; with one, the plant counts it instead (docs/real-robot.md)
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
    mapfile -t PRIO < <(prio disturbance_observer)
    disturbance_observer --ros-args "${PF[@]}" -p "disturbance_observer:mode:=$MODE" -p "disturbance_observer:csv:=$LOGS/${CTRL}_estimates.csv" \
        "${PRIO[@]}" > "$LOGS/${CTRL}_disturbance_observer.log" 2>&1 &
    PIDS+=($!)
    if [ "$MODEL" = raw ]; then   # the first stage of the chain: imu/data_raw + wheel_encoder -> joint_states
        SYNC=()   # the emulated moteus robot's IMU has its own driver and rate: the newest sample at each encoder's
        [ "$BACKEND" = moteus ] && SYNC=(-p "state_estimator:imu_sync:=latest")
        mapfile -t PRIO < <(prio state_estimator)
        state_estimator --ros-args "${PF[@]}" -p "state_estimator:mode:=$MODE" "${SYNC[@]}" "${PRIO[@]}" \
            > "$LOGS/${CTRL}_state_estimator.log" 2>&1 &
        PIDS+=($!)
    fi
    if [ "$ROBOT_STATE" = 1 ]; then   # a view of the states: odom, robot_description, wheel_joint_states
        robot_state --ros-args "${PF[@]}" > "$LOGS/${CTRL}_robot_state.log" 2>&1 &
        PIDS+=($!)
        # it reads joint_states: without raw sensors the plant's first topic, so the plant counts it
        [ "$MODEL" = raw ] || SUBS=$((SUBS + 1))
    fi
    mapfile -t PRIO < <(prio dscndo_controller)
    dscndo_controller --ros-args "${PF[@]}" -p "dscndo_controller:mode:=$MODE" -p "dscndo_controller:use_observer:=$USE_OBS" -p "dscndo_controller:law:=$LAW" \
        "${PRIO[@]}" > "$LOGS/${CTRL}_dscndo_controller.log" 2>&1 &
    PIDS+=($!)
    : > "$LOGS/${CTRL}_${SIDE}.log"   # exists before tail opens it
    if [ -z "$ROBOT" ]; then
        plant_sim --ros-args "${PF[@]}" "${PLANT_EXTRA[@]}" -p "plant_sim:expected_subscribers:=$SUBS" \
            -p "plant_sim:csv:=$LOGS/${CTRL}.csv" >> "$LOGS/${CTRL}_plant_sim.log" 2>&1 &
    else
        LINK=()
        if [ "$BACKEND" = moteus ]; then   # the emulated robot: its own process, its pty's path on its first line
            CHRT=()
            [ "$PRIORITY" = 0 ] || CHRT=(chrt -f "$PRIORITY")
            "${CHRT[@]}" mwip_moteus_emulator --params "${PARAMS[@]}" --link "$LOGS/${CTRL}_fdcanusb" --hold "${EMULATOR_OPTIONS[@]}" \
                > "$LOGS/${CTRL}_moteus_emulator.log" 2>&1 &
            EMU=$!
            PIDS+=("$EMU")
            for _ in $(seq 1 300); do   # up to 30 s (a loaded machine imports slowly)
                grep -q '^fdcanusb: ' "$LOGS/${CTRL}_moteus_emulator.log" 2>/dev/null && break
                kill -0 "$EMU" 2>/dev/null || break
                sleep 0.1
            done
            if ! grep -q '^fdcanusb: ' "$LOGS/${CTRL}_moteus_emulator.log" 2>/dev/null; then
                echo "run_experiment: the moteus emulator did not start (see $(shown "$LOGS")/${CTRL}_moteus_emulator.log)" >&2
                exit 1
            fi
            LINK=(-p "wheel_driver:moteus.path:=$LOGS/${CTRL}_fdcanusb")
        fi
        SUMMARIES+=("$LOGS/${CTRL}_driver.json")
        mapfile -t PRIO < <(prio wheel_driver)
        wheel_driver --ros-args "${PF[@]}" "${DRIVER_EXTRA[@]}" "${LINK[@]}" "${PRIO[@]}" \
            -p "wheel_driver:expected_subscribers:=$SUBS" -p "wheel_driver:summary_json:=$LOGS/${CTRL}_driver.json" \
            >> "$LOGS/${CTRL}_wheel_driver.log" 2>&1 &
    fi
    PLANT=$!
    PIDS+=("$PLANT")
    tail --pid="$PLANT" -n +1 -f "$LOGS/${CTRL}_${SIDE}.log" &   # show the robot side's progress live
    TAIL=$!
    code=0
    wait "$PLANT" || code=$?
    wait "$TAIL" 2>/dev/null || true   # tail --pid ends by itself within a second of the plant
    TAIL=""
    stop_all
    [ "$INTERRUPTED" = 0 ] || code=130   # (the wait returned at the signal; the plant has stopped since)
    case "$code" in
        0) ;;
        3) FELL+=("$CTRL")
           if [ "$i" -lt $(( ${#LAW_LIST[@]} - 1 )) ]; then   # said at the end too: here only when runs follow
               echo "run_experiment: the robot FELL in the $CTRL run; the next run and the report go on" >&2
           fi ;;
        130|143) INTERRUPTED=1 ;;
        *) echo "run_experiment: $SIDE failed in the $CTRL run (exit $code); see $(shown "$LOGS")/" >&2
           exit 1 ;;
    esac
    RAN+=("$CTRL")
    if [ "$RECORD" = 1 ]; then
        tail -n 1 "$LOGS/${CTRL}_mcap_recorder.log"
    fi
    if [ "$BACKEND" = moteus ]; then   # its counters (frames, lost, watchdog trips) are its last line
        tail -n 1 "$LOGS/${CTRL}_moteus_emulator.log"
    fi
done
trap 'echo; echo "run_experiment: interrupted, stopping" >&2; exit 130' INT TERM

REPORT="$OUT/${STAMP}_report"
N=${#RAN[@]}
if [ "$INTERRUPTED" = 1 ]; then
    echo "=== report of the runs so far (${RAN[*]:-none}; interrupted) ==="
else
    echo "=== report ==="
fi
reported=0
if [ "$N" -gt 0 ]; then
    if [ "$RECORD" = 1 ]; then
        mwip_report "${RUNS[@]:0:$N}" --labels "${RAN[@]}" --out "$REPORT" && reported=1
        if [ "$reported" = 1 ] && [ -n "$ROBOT" ]; then   # the period timing of each run's robot side, added
            python -m mwip_ros.cli.experiment --timing "${SUMMARIES[@]:0:$N}" "${RAN[@]}" | tee -a "$REPORT/metrics.md"
        fi
    else
        mwip_report "${RUNS[@]:0:$N}" --estimates "${ESTIMATES[@]:0:$N}" --labels "${RAN[@]}" --out "$REPORT" \
            && reported=1
    fi
fi
[ "$reported" = 1 ] || [ "$INTERRUPTED" = 1 ] || exit 1
echo
if [ "$RECORD" = 1 ] && [ "$N" -gt 0 ]; then
    bags=()
    for b in "${RUNS[@]:0:$N}"; do bags+=("$(shown "$b")"); done
    echo "bags:  " "${bags[@]}"
fi
if [ "$reported" = 1 ]; then
    figures=""   # what mwip_report wrote (pitch_estimate.png with raw sensors, animation.gif unless it could not)
    for f in fig3.png observer.png pitch_estimate.png animation.gif; do
        if [ -f "$REPORT/$f" ]; then figures="${figures:+$figures, }$f"; fi
    done
    echo "report: $(shown "$REPORT")/metrics.md (figures $figures)"
else
    echo "report: none (no run recorded anything to report before the interruption)"
fi
echo "logs:   $(shown "$LOGS")/"
if [ "$INTERRUPTED" = 1 ]; then
    echo "run_experiment: interrupted${FELL[*]:+ (the robot fell in: ${FELL[*]})}; the report covers ${RAN[*]:-no run} (exit 130)" >&2
    exit 130
fi
if [ ${#FELL[@]} -gt 0 ]; then
    echo "run_experiment: the robot fell in: ${FELL[*]} (exit 3)" >&2
    exit 3
fi
