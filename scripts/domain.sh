# Source me (bash): mwip_domain NAME picks the ROS domain of a run and holds it until the run ends.
#
# A ROS_DOMAIN_ID already in the environment is the user's: it is kept (checked to be a number in 0..232).
# Otherwise a free one in 1..101 is chosen (ROS 2's documented range without port clashes, leaving 0,
# the default, to the user's own graph). Either way the id is locked for as long as this shell (and the
# nodes it starts, which inherit the lock) runs, so two runs never share a domain: a second run asked for
# a domain in use stops with exit 2. The locks are files ${TMPDIR:-/tmp}/mwip_ros-domain-ID.lock, taken
# with flock(2), released by the kernel when their last holder exits (even on kill -9).
# The tests' process helper (test/graphproc.py) takes the same locks.

_mwip_lock_domain() {   # $1 = id; holds the lock on fd MWIP_DOMAIN_FD, or returns 1
    local fd
    exec {fd}>"${TMPDIR:-/tmp}/mwip_ros-domain-$1.lock" || return 1
    if command -v flock >/dev/null 2>&1; then
        flock -n "$fd" || { exec {fd}>&-; return 1; }
    else   # flock(1) missing: the lock belongs to the open file, so a child may take it on our descriptor
        python3 -c 'import fcntl, sys; fcntl.flock(int(sys.argv[1]), fcntl.LOCK_EX | fcntl.LOCK_NB)' "$fd" \
            2>/dev/null || { exec {fd}>&-; return 1; }
    fi
    MWIP_DOMAIN_FD=$fd
}

mwip_domain() {   # $1 = the program's name for its messages
    local who="$1" id start i
    if [ -n "${ROS_DOMAIN_ID:-}" ]; then
        if ! [[ "$ROS_DOMAIN_ID" =~ ^[0-9]+$ ]] || [ "$ROS_DOMAIN_ID" -gt 232 ]; then
            echo "$who: ROS_DOMAIN_ID must be a number in 0..232 (0..101 avoids port clashes), got '$ROS_DOMAIN_ID'" >&2
            return 2
        fi
        if ! _mwip_lock_domain "$ROS_DOMAIN_ID"; then
            echo "$who: ROS_DOMAIN_ID=$ROS_DOMAIN_ID is in use by another mwip_ros run; unset ROS_DOMAIN_ID to have a free one chosen" >&2
            return 2
        fi
        export ROS_DOMAIN_ID
        echo "$who: ROS_DOMAIN_ID=$ROS_DOMAIN_ID (yours, from the environment)"
        return 0
    fi
    start=$(( RANDOM % 101 ))
    for i in $(seq 0 100); do
        id=$(( (start + i) % 101 + 1 ))
        if _mwip_lock_domain "$id"; then
            export ROS_DOMAIN_ID="$id"
            echo "$who: ROS_DOMAIN_ID=$ROS_DOMAIN_ID (a free one, chosen; set ROS_DOMAIN_ID to choose it yourself)"
            return 0
        fi
    done
    echo "$who: every ROS domain 1..101 is in use by other mwip_ros runs; set ROS_DOMAIN_ID" >&2
    return 2
}
