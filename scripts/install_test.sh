#!/usr/bin/env bash
# Tests the README's install recipe and the systemd unit on this machine, as root, without a
# running systemd (CI containers have none):
#
# 1. `systemd-analyze security --offline=true` rates daemon/systemd/deard.service at most 2.0.
# 2. The recipe between README's `install-recipe` markers runs line by line as written (with
#    `sudo` a no-op for root; the `systemctl` line is skipped: no systemd to talk to).
# 3. `systemd-analyze verify` accepts the installed unit (its binary and user now exist).
# 4. The unit's ExecStart runs as the unit would run it: as User=/Group=/SupplementaryGroups=,
#    with its Environment=, UMask= and WorkingDirectory=, no capabilities, no new privileges,
#    and the sandbox emulated with namespaces: the root file system read-only but for
#    the RuntimeDirectory (ProtectSystem=strict), no /dev/shm (InaccessiblePaths=), a private
#    /tmp (PrivateTmp=yes), no home directories (ProtectHome=yes), no network
#    (PrivateNetwork=yes). It is traced (strace) to check every system call it makes against
#    the unit's SystemCallFilter= and that it never maps memory writable and executable
#    (MemoryDenyWriteExecute=yes), and systemd's notify protocol is played by a socket here:
#    READY=1 and WATCHDOG=1 must arrive.
# 5. Apps as other users: `dear dump`, run outside the sandbox from another directory with the
#    README's client setting (DEAR_IOX2_ROOT) as a user in the service's group (added to it
#    with the README's command), receives frames; a user outside the group is refused with an
#    error that says why; a client without the setting (default root) does not see the
#    service; nothing of the daemon's is in /dev/shm. The C example (client-c/examples/
#    receive.c, linked here against target/release/libdear_client.a) and a Python script
#    (`import dear`, client-py, with the system python3) each receive 5 frames as the same
#    user in the group: a Rust, a C and a Python app of another user than the daemon's.
# 6. SIGTERM stops the daemon cleanly (exit 0, "stopped" logged, STOPPING=1 sent).
#
# Everything installed is removed afterwards, also on failure. Refuses to run where deard is
# already installed. About 20-40 s. Needs root, strace, setpriv, unshare, python3,
# systemd-analyze and cc, and release builds: cargo build --release -p deard -p dear-cli, then
# cargo build --release -p dear-client-c on its own (built with the others, the SDK in
# libdear_client.a would get the CLI's features: the pipeline and tract).
set -euo pipefail
cd "$(dirname "$0")/.."
unit=daemon/systemd/deard.service
max_exposure=2.0

SCRIPT_NAME=install_test
. scripts/lib.sh

[ "$(id -u)" = 0 ] || fail "must run as root (it installs into /usr/local and /etc, adds a user)"
for tool in systemd-analyze strace setpriv unshare python3 useradd userdel cc; do
    command -v "$tool" >/dev/null || fail "$tool is not installed"
done
build="cargo build --release -p deard -p dear-cli && cargo build --release -p dear-client-c"
for f in target/release/deard target/release/dear target/release/libdear_client.a; do
    [ -f "$f" ] || fail "$f missing: $build"
done

# --- 1. exposure --------------------------------------------------------------------------
step "systemd-analyze security --offline=true $unit"
security=$(systemd-analyze security --offline=true "$unit" 2>&1) \
    || fail "systemd-analyze security failed: $security"
exposure=$(sed -n 's/.*Overall exposure level for deard.service: \([0-9.]*\) .*/\1/p' <<<"$security")
[ -n "$exposure" ] || fail "no 'Overall exposure level' line in: $security"
echo "exposure $exposure (at most $max_exposure)"
python3 -c "import sys; sys.exit(0 if float('$exposure') <= $max_exposure else 1)" \
    || fail "exposure $exposure > $max_exposure:
$(grep '✗' <<<"$security")"

# --- 2. the recipe, as written ------------------------------------------------------------
installed=(/usr/local/bin/deard /usr/local/bin/dear /usr/local/share/deard
           /usr/local/share/doc/deard /etc/deard /etc/systemd/system/deard.service)
for p in "${installed[@]}"; do
    [ ! -e "$p" ] || fail "$p exists: deard looks installed here; not touching it"
done
getent passwd deard >/dev/null && fail "user deard exists: deard looks installed here"
getent group dear >/dev/null && fail "group dear exists: deard looks installed here"
# Two app users: one the README adds to the group, one it does not.
app_user=dear-test-app
other_user=dear-test-other
for u in "$app_user" "$other_user"; do
    getent passwd "$u" >/dev/null && fail "user $u exists (a previous run's?): userdel it"
done

# In /run, not /tmp: the sandboxed daemon has a /tmp of its own and must reach the notify socket.
scratch=$(mktemp -d /run/deard-install-test.XXXXXX)
chmod 755 "$scratch"
daemon_pid=
cleanup() {
    local rc=$?
    if [ -n "$daemon_pid" ]; then
        # The deard process itself: killing strace would only detach it.
        local pid
        for pid in $(pgrep -u deard -x deard); do kill -KILL "$pid" 2>/dev/null || true; done
        kill -KILL "$daemon_pid" 2>/dev/null || true
        wait "$daemon_pid" 2>/dev/null || true
    fi
    if [ -n "${notify_pid:-}" ]; then kill "$notify_pid" 2>/dev/null || true; fi
    rm -rf "${installed[@]}" /run/deard
    # The users and the group (anything of theirs in /dev/shm too, should a check fail).
    find /dev/shm -maxdepth 1 \( -user deard -o -user "$app_user" \) -delete 2>/dev/null || true
    remove_accounts dear "$app_user" "$other_user" deard
    if [ "$rc" = 0 ]; then
        rm -rf "$scratch"
        echo "install_test: ok"
    else
        echo "install_test: logs, trace and dumps kept in $scratch" >&2
    fi
    exit "$rc"
}
trap cleanup EXIT

# The recipe's lines from README, between the install-recipe markers, inside the sh block.
# shellcheck disable=SC2016 # backticks of the Markdown fence, not an expansion
recipe=$(sed -n '/^<!-- install-recipe/,/^<!-- \/install-recipe -->/p' README.md \
    | sed -n '/^```sh$/,/^```$/p' | sed '1d;$d')
[ -n "$recipe" ] || fail "no install recipe between <!-- install-recipe --> markers in README.md"
# shellcheck disable=SC2317 # called by the recipe's lines through eval
sudo() { "$@"; }   # root already
step "README install recipe"
while IFS= read -r line; do
    case "$line" in
        *systemctl*) echo "skipped (no running systemd): $line"; continue ;;
    esac
    echo "+ $line"
    eval "$line" || fail "recipe line failed: $line"
done <<<"$recipe"
unset -f sudo

# --- 3. verify ----------------------------------------------------------------------------
step "systemd-analyze verify /etc/systemd/system/deard.service"
# Without a running systemd, verify may complain about the manager itself; only lines about
# deard.service count.
verify=$(systemd-analyze verify /etc/systemd/system/deard.service 2>&1) || true
if grep -i 'deard' <<<"$verify" | grep -v '^$'; then
    fail "systemd-analyze verify reports problems with the unit (above)"
fi
echo "verify: no complaints about deard.service"

# --- 4. run ExecStart as the unit would ---------------------------------------------------
# One value of a [Service] key of the installed unit (all values joined for Environment=).
unit_value() {
    sed -n "s/^$1=//p" /etc/systemd/system/deard.service | paste -sd ' '
}
exec_start=$(unit_value ExecStart)
user=$(unit_value User)
group=$(unit_value Group)
supplementary=$(unit_value SupplementaryGroups)
environment=$(unit_value Environment)
umask_value=$(unit_value UMask)
workdir=$(unit_value WorkingDirectory)
runtime_dir=/run/$(unit_value RuntimeDirectory)
runtime_mode=$(unit_value RuntimeDirectoryMode)
if [ -z "$exec_start" ] || [ -z "$user" ] || [ "$runtime_dir" = /run/ ]; then
    fail "ExecStart=, User= or RuntimeDirectory= missing from the unit"
fi
echo "ExecStart=$exec_start as $user:$group (+$supplementary) in ${workdir:-/}, $environment"

# What systemd does for RuntimeDirectory=.
install -d -m "${runtime_mode:-0755}" -o "$user" -g "$group" "$runtime_dir"

# systemd's side of Type=notify and WatchdogSec=: a datagram socket the daemon may write to.
notify_socket=$scratch/notify.sock
python3 - "$notify_socket" >"$scratch/notify.log" <<'EOF' &
import os, socket, sys
s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
s.bind(sys.argv[1])
os.chmod(sys.argv[1], 0o666)
while True:
    msg = s.recv(4096).decode()
    print(msg.replace("\n", " "), flush=True)
EOF
notify_pid=$!
for _ in $(seq 50); do [ -S "$notify_socket" ] && break; sleep 0.1; done
[ -S "$notify_socket" ] || fail "notify socket not created"
watchdog_s=$(unit_value WatchdogSec)
# A short watchdog here (the unit's 30 s would not ping within the test); the period only
# changes how often the frame loop pings.
watchdog_usec=2000000

groups_arg=()
if [ -n "$supplementary" ]; then groups_arg=(--groups "$(tr ' ' ',' <<<"$supplementary")"); fi
# ExecStart= and Environment= are word lists (no quoting in this unit), split as systemd does.
# shellcheck disable=SC2016,SC2206 # the sh -c script expands its own arguments
sandboxed_run=(
    unshare --mount --net --propagation private
    sh -c '
        set -e
        mount --bind "$1" "$1"                   # RuntimeDirectory: writable
        mount -t tmpfs -o mode=1777 tmpfs /tmp   # PrivateTmp=yes
        mount -t tmpfs -o ro,mode=755 tmpfs /home
        mount -t tmpfs -o ro,mode=700 tmpfs /root # ProtectHome=yes
        mount -t tmpfs -o ro,mode=000 tmpfs /dev/shm # InaccessiblePaths=/dev/shm
        mount -o remount,bind,ro /               # ProtectSystem=strict
        shift
        umask "$1"; shift
        cd "$1"; shift
        exec "$@"
    ' sandbox "$runtime_dir" "${umask_value:-0022}" "${workdir:-/}"
    setpriv --reuid "$user" --regid "$group" "${groups_arg[@]}"
    --inh-caps=-all --bounding-set=-all --no-new-privs
    env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin $environment
    NOTIFY_SOCKET="$notify_socket" WATCHDOG_USEC=$watchdog_usec
    $exec_start
)
step "starting the unit's ExecStart in the emulated sandbox (WatchdogSec=$watchdog_s)"
strace -f -qq -o "$scratch/trace" "${sandboxed_run[@]}" >"$scratch/deard.log" 2>&1 &
daemon_pid=$!
wait_for_serving "$daemon_pid" "$scratch/deard.log" 30 deard
grep -q "root=/run/deard/iceoryx2" "$scratch/deard.log" \
    || fail "deard does not use /run/deard/iceoryx2: $(cat "$scratch/deard.log")"

# --- 5. clients ---------------------------------------------------------------------------
# Apps on the device: outside the sandbox, another working directory, the environment the
# README gives clients, as users other than the daemon's.
client_root=$(sed -n 's/^DEAR_IOX2_ROOT=\([^ ]*\) dear watch.*/\1/p' README.md)
[ "$client_root" = /run/deard/iceoryx2 ] \
    || fail "README's client example does not set DEAR_IOX2_ROOT=/run/deard/iceoryx2: '$client_root'"
# The README's command that lets a user's apps receive frames, for this test's user.
add_to_group=$(sed -n 's/^sudo usermod -aG dear "\$USER".*/usermod -aG dear/p' README.md)
[ -n "$add_to_group" ] || fail "README does not say 'sudo usermod -aG dear \"\$USER\"'"
useradd --no-create-home --shell /usr/sbin/nologin "$app_user"
useradd --no-create-home --shell /usr/sbin/nologin "$other_user"
$add_to_group "$app_user"
install -d -o "$app_user" "$scratch/app"
install -d -o "$other_user" "$scratch/other"
as_client() {  # USER DIR ARGS...: a dear command as USER from /, with the clients' setting
    local who=$1 dir=$2; shift 2
    (cd / && env -i PATH=/usr/bin:/bin DEAR_IOX2_ROOT="$client_root" \
        setpriv --reuid "$who" --regid "$who" --init-groups /usr/local/bin/dear "$@" \
        --out "$dir/dump")
}
step "dear dump as $app_user (in group dear) from /, DEAR_IOX2_ROOT=$client_root"
as_client "$app_user" "$scratch/app" dump --count 5 --timeout-s 30 >"$scratch/dump-app.log" 2>&1 \
    || fail "$app_user got no frames: $(cat "$scratch/dump-app.log" "$scratch/deard.log")"
n=$(find "$scratch/app/dump/frames" -name '*.depth.png' | wc -l)
[ "$n" = 5 ] || fail "$app_user wrote $n depth frames, not 5"
echo "$app_user: 5 frames"

# An app in C: the SDK's C example, linked against the static library as README's "C" says,
# as the same user with the same setting.
step "C example (client-c/examples/receive.c) as $app_user, DEAR_IOX2_ROOT=$client_root"
if ar t target/release/libdear_client.a | grep -q tract; then
    fail "target/release/libdear_client.a holds tract: build -p dear-client-c on its own ($build)"
fi
cc -O2 -Iclient-c/include client-c/examples/receive.c target/release/libdear_client.a \
    -lgcc_s -lutil -lrt -lpthread -lm -ldl -lc -o "$scratch/receive" \
    || fail "cannot build the C example"
chmod 755 "$scratch/receive"
rc=0
(cd / && env -i PATH=/usr/bin:/bin DEAR_IOX2_ROOT="$client_root" \
    setpriv --reuid "$app_user" --regid "$app_user" --init-groups \
    "$scratch/receive" dear/cam0/frames 5 30000) >"$scratch/receive-app.log" 2>&1 || rc=$?
[ "$rc" = 0 ] || fail "the C example as $app_user exited $rc: $(cat "$scratch/receive-app.log")"
n=$(grep -c '^frame [0-9]* [0-9]*x[0-9]* valid=[1-9][0-9]* run=[0-9a-f]* seq=[0-9]*$' \
    "$scratch/receive-app.log" || true)
[ "$n" = 5 ] || fail "the C example printed $n frame lines, not 5: $(cat "$scratch/receive-app.log")"
echo "$app_user (C): $(tail -1 "$scratch/receive-app.log")"

# An app in Python: the `dear` package (client-py/python/dear, built into place by
# scripts/setup.sh) copied where the app user can read it, run by the system's python3 with its
# numpy (the project's .venv lives in the checkout, which other users may not reach).
step "Python (import dear) as $app_user, DEAR_IOX2_ROOT=$client_root"
py=/usr/bin/python3
"$py" -c 'import numpy' 2>/dev/null \
    || fail "$py with numpy is needed (scripts/setup.sh installs python3-numpy)"
ext=$(find client-py/python/dear -maxdepth 1 -name '_dear*.so' | head -1)
[ -n "$ext" ] || fail "client-py is not built (scripts/setup.sh builds it into client-py/python/dear)"
suffix=$("$py" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')
[ "${ext%"$suffix"}" != "$ext" ] \
    || fail "$ext was built for another Python than $py (extension suffix $suffix)"
install -d -m 755 "$scratch/py"
cp -r client-py/python/dear "$scratch/py/"
chmod -R a+rX "$scratch/py"
cat >"$scratch/py/receive.py" <<'PY'
import sys

import dear

with dear.Subscriber(sys.argv[1]) as sub:
    for _ in range(int(sys.argv[2])):
        frame = sub.wait(30.0)
        if frame is None:
            sys.exit(f"no frame from {sub.service} in 30 s")
        with frame:
            h = frame.header
            valid = int((frame.depth > 0).sum())
            print(f"frame {h.frame_id} {h.width}x{h.height} valid={valid} seq={h.sequence}")
PY
rc=0
(cd / && env -i PATH=/usr/bin:/bin DEAR_IOX2_ROOT="$client_root" PYTHONPATH="$scratch/py" \
    setpriv --reuid "$app_user" --regid "$app_user" --init-groups \
    "$py" "$scratch/py/receive.py" dear/cam0/frames 5) >"$scratch/python-app.log" 2>&1 || rc=$?
[ "$rc" = 0 ] || fail "the Python app as $app_user exited $rc: $(cat "$scratch/python-app.log")"
n=$(grep -c '^frame [0-9]* [0-9]*x[0-9]* valid=[1-9][0-9]* seq=[0-9]*$' "$scratch/python-app.log" || true)
[ "$n" = 5 ] || fail "the Python app printed $n frame lines, not 5: $(cat "$scratch/python-app.log")"
echo "$app_user (Python): $(tail -1 "$scratch/python-app.log")"

step "dear dump as $other_user (not in the group): refused, and says why"
rc=0
as_client "$other_user" "$scratch/other" dump --count 1 --timeout-s 5 >"$scratch/dump-other.log" 2>&1 || rc=$?
[ "$rc" != 0 ] || fail "$other_user, outside the group, received frames: $(cat "$scratch/dump-other.log")"
grep -q "Permission denied" "$scratch/dump-other.log" && grep -q "$client_root" "$scratch/dump-other.log" \
    || fail "$other_user's error does not name the root and the permission: $(cat "$scratch/dump-other.log")"
echo "$other_user: $(tail -1 "$scratch/dump-other.log")"
listing=$(env -i PATH=/usr/bin:/bin DEAR_IOX2_ROOT="$client_root" \
    setpriv --reuid "$other_user" --regid "$other_user" --init-groups /usr/local/bin/dear list 2>&1) \
    && fail "dear list as $other_user succeeded (it cannot enter the root): $listing"
grep -q "Permission denied" <<<"$listing" || fail "dear list as $other_user does not say why: $listing"

# The service is not in the default root: a client there does not see it. `dear list` with a
# private /dev/shm, so it neither sees nor touches the host's /dev/shm/dear.
listing=$(unshare --mount --propagation private sh -c \
    'mount -t tmpfs tmpfs /dev/shm && exec "$@"' list \
    env -i PATH=/usr/bin:/bin setpriv --reuid "$app_user" --regid "$app_user" --init-groups \
    /usr/local/bin/dear list 2>&1) || fail "dear list (default root) failed: $listing"
grep -q "no DEAR frame services found" <<<"$listing" \
    || fail "a service is visible under the default root /dev/shm/dear: $listing"
listing=$(env -i PATH=/usr/bin:/bin DEAR_IOX2_ROOT="$client_root" \
    setpriv --reuid "$app_user" --regid "$app_user" --init-groups /usr/local/bin/dear list 2>&1) \
    || fail "dear list under $client_root failed: $listing"
grep -q "^ *dear/cam0/frames " <<<"$listing" || fail "dear list does not show the service: $listing"
echo "$listing"
echo "dear list: the service under $client_root only"

# Where the transport's files are: all under the root, none in /dev/shm; the root reachable by
# the group only.
shm_files=$(find /dev/shm -maxdepth 1 \( -user "$user" -o -user "$app_user" \) -printf '%f\n')
[ -z "$shm_files" ] || fail "files of $user or $app_user in /dev/shm: $shm_files"
root_mode=$(stat -c '%a %U %G' "$client_root")
[ "$root_mode" = "770 $user $group" ] || fail "$client_root is '$root_mode', not '770 $user $group'"
runtime_stat=$(stat -c '%a %U %G' "$runtime_dir")
[ "$runtime_stat" = "750 $user $group" ] || fail "$runtime_dir is '$runtime_stat', not '750 $user $group'"
echo "transport: $(find "$client_root" -type f | wc -l) files under $client_root ($root_mode), none in /dev/shm"

# The frame loop pings at half the period (1 s here): a second ping shows it is periodic.
for _ in $(seq 50); do
    [ "$(grep -c WATCHDOG=1 "$scratch/notify.log")" -ge 2 ] && break
    sleep 0.1
done
[ "$(grep -c WATCHDOG=1 "$scratch/notify.log")" -ge 2 ] \
    || fail "fewer than 2 WATCHDOG=1 pings in 5 s: $(cat "$scratch/notify.log")"

# --- 6. stop ------------------------------------------------------------------------------
step "SIGTERM"
deard_pid=$(pgrep -u "$user" -x deard) || fail "no deard process of $user"
kill -TERM "$deard_pid"
rc=0
wait "$daemon_pid" || rc=$?
daemon_pid=
[ "$rc" = 0 ] || fail "deard exited $rc on SIGTERM: $(tail -20 "$scratch/deard.log")"
grep -q stopped "$scratch/deard.log" || fail "no 'stopped' in the log"
kill "$notify_pid"; wait "$notify_pid" 2>/dev/null || true; notify_pid=
for msg in READY=1 WATCHDOG=1 STOPPING=1; do
    grep -q "$msg" "$scratch/notify.log" || fail "no $msg on the notify socket: $(cat "$scratch/notify.log")"
done
echo "notify: $(sort "$scratch/notify.log" | uniq -c | paste -sd ' ')"

# --- 4b. the trace against the unit's system call filter and MemoryDenyWriteExecute -------
step "system calls against SystemCallFilter=, writable+executable mappings"
# From deard's exec on (seccomp applies before it; the lines before are the sandbox set-up).
start=$(grep -n 'execve("/usr/local/bin/deard"' "$scratch/trace" | head -1 | cut -d: -f1)
[ -n "$start" ] || fail "deard's execve not in the trace"
tail -n +"$start" "$scratch/trace" >"$scratch/deard.trace"
used=$(sed -n 's/^[0-9]\+ \+\([a-z0-9_]\+\)(.*/\1/p' "$scratch/deard.trace" | sort -u)
[ -n "$used" ] || fail "no system calls parsed from the trace"
# The system calls of filter groups and names, groups expanded recursively.
syscalls_of() {
    local item
    for item in "$@"; do
        case "$item" in
            @*) systemd-analyze syscall-filter "$item" 2>/dev/null \
                    | sed -n 's/^    \([@a-z0-9_-]\+\)$/\1/p' \
                    | while read -r member; do syscalls_of "$member"; done ;;
            *) echo "$item" ;;
        esac
    done | sort -u
}
# The allowed set as systemd builds it from the SystemCallFilter= lines: the first, an allow
# list; a later one starting with ~ removes its calls from it.
allowed=""
while read -r filter; do
    case "$filter" in
        "~"*) # shellcheck disable=SC2086 # a list of groups
              allowed=$(comm -23 <(echo "$allowed") <(syscalls_of ${filter#\~})) ;;
        *)    # shellcheck disable=SC2086
              allowed=$(sort -u <(echo "$allowed") <(syscalls_of $filter)) ;;
    esac
done < <(sed -n 's/^SystemCallFilter=//p' /etc/systemd/system/deard.service)
[ "$(wc -l <<<"$allowed")" -gt 100 ] || fail "could not expand the unit's SystemCallFilter"
outside=$(comm -23 <(echo "$used") <(echo "$allowed"))
[ -z "$outside" ] || fail "system calls outside the unit's SystemCallFilter: $outside"
echo "$(wc -l <<<"$used") distinct system calls, all allowed: $(paste -sd " " <<<"$used")"
if grep -E '^[0-9]+ +(mmap|mprotect|pkey_mprotect)\(.*PROT_EXEC' "$scratch/deard.trace" \
    | grep -E 'PROT_WRITE|^[0-9]+ +(mprotect|pkey_mprotect)\('; then
    fail "writable+executable mapping or mprotect(PROT_EXEC), refused by MemoryDenyWriteExecute"
fi
echo "no writable+executable mappings"
