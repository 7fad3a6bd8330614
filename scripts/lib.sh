# shellcheck shell=bash
# Helpers the test scripts share; source it after `cd` to the repository root, with
# SCRIPT_NAME set to the name its failures are reported under.
#   fail MESSAGE   report SCRIPT_NAME: FAIL: MESSAGE and exit 1
#   step MESSAGE   a progress heading, as scripts/test.sh prints its own
#   now; since T   seconds since T (from `now`), one decimal, e.g. "12.3"
#   wait_for_line PID LOG PATTERN SECONDS LABEL, wait_for_serving PID LOG SECONDS LABEL,
#   remove_accounts GROUP USER...   (below)

fail() { echo "${SCRIPT_NAME:?}: FAIL: $*" >&2; exit 1; }
step() { echo "== $*"; }
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

# wait_for_line PID LOG PATTERN SECONDS LABEL: wait until the process PID writes a line matching
# the grep PATTERN to LOG; fail naming LABEL (with the log) if it exits first or has not written
# it within SECONDS.
wait_for_line() {
    local pid=$1 log=$2 pattern=$3 seconds=$4 label=$5
    for _ in $(seq $((seconds * 10))); do
        grep -q "$pattern" "$log" && return 0
        kill -0 "$pid" 2>/dev/null || fail "$label exited: $(cat "$log")"
        sleep 0.1
    done
    grep -q "$pattern" "$log" || fail "$label did not say '$pattern' in $seconds s: $(cat "$log")"
}

# wait_for_serving PID LOG SECONDS LABEL: wait_for_line for a daemon's "serving".
wait_for_serving() { wait_for_line "$1" "$2" serving "$3" "$4"; }

# remove_accounts GROUP USER...: delete those of the users and the group that exist (the
# cleanup of the tests that create them).
remove_accounts() {
    local group=$1 u
    shift
    for u in "$@"; do
        if getent passwd "$u" >/dev/null; then userdel "$u"; fi
    done
    if getent group "$group" >/dev/null; then groupdel "$group"; fi
}
