# Helpers the test scripts share; source it after `cd` to the repository root, with
# SCRIPT_NAME set to the name its failures are reported under.
#   fail MESSAGE   report SCRIPT_NAME: FAIL: MESSAGE and exit 1
#   step MESSAGE   a progress heading, as scripts/test.sh prints its own
#   now; since T   seconds since T (from `now`), one decimal, e.g. "12.3"

fail() { echo "${SCRIPT_NAME:?}: FAIL: $*" >&2; exit 1; }
step() { echo "== $*"; }
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }
