# Source me (bash):  source scripts/env.sh
# Activates .venv and sets the ROS 2 / matplotlib environment for mwip_ros.
# Run scripts/setup.sh first to create .venv.

_mwip_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

if [ ! -f "$_mwip_root/.venv/bin/activate" ]; then
    echo "env.sh: $_mwip_root/.venv missing; run scripts/setup.sh first" >&2
    unset _mwip_root
    return 1 2>/dev/null || exit 1
fi

# shellcheck disable=SC1091
. "$_mwip_root/.venv/bin/activate"

# The venv is an ament prefix (.venv/share/<pkg>/...), but nothing registers it.
case ":${AMENT_PREFIX_PATH:-}:" in
    *":$VIRTUAL_ENV:"*) ;;
    *) export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
esac

export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# ROS_DOMAIN_ID is left as you have it (unset: ROS's default, 0), so every terminal that sources this
# file sees the same graph. scripts/run_experiment.sh, test.sh and bench.sh pick a free domain of their
# own when you have not set one (scripts/domain.sh).
export MPLBACKEND=Agg

unset _mwip_root
