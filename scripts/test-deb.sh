#!/usr/bin/env bash
# Tests the Debian packages built by scripts/build-deb.sh (target/debian/deard_VERSION_ARCH.deb):
#
# 1. The amd64 package's control fields and file list; the arm64 package's too (architecture
#    arm64, the same files as the amd64 one, its deard and dear aarch64 ELF executables, and,
#    where qemu-aarch64 is installed, its deard reads the packaged example configuration).
# 2. dpkg -i of the amd64 package on this machine: the files, the conffile, the unit (the
#    repository's daemon/systemd/deard.service with /usr/local/ read as /usr/, and accepted by
#    systemd-analyze verify), the system user `deard` in group `dear`, the unit enabled for
#    boot (multi-user.target.wants) but not configured: no /etc/deard/deard.toml, so its
#    ConditionPathExists= keeps it from starting.
# 3. Configuring it as the README says (the example copied to /etc/deard/deard.toml: the
#    packaged sample capture, looping), then the unit's ExecStart as the unit's User=/Group=
#    with its Environment= and RuntimeDirectory= (no sandbox here: scripts/install_test.sh
#    tests the sandbox of the same unit): it serves, and `dear list` and `dear dump` of the
#    package, run as another user added to group `dear`, see the service and receive 5 frames.
#    SIGTERM stops it with exit status 0.
# 4. dpkg --purge: the files, the configuration, the enablement and the state are gone; the
#    user and the group stay (Debian keeps system users), and this test removes them.
#
# Runs as root on a machine where deard is not installed (no package, no user deard, no group
# dear, no /run/deard), and leaves it so, also on failure. About 30 s.
set -euo pipefail
cd "$(dirname "$0")/.."

SCRIPT_NAME=test-deb
. scripts/lib.sh

[ "$(id -u)" = 0 ] || fail "must run as root (it installs the package and adds users)"
for tool in dpkg dpkg-deb setpriv systemd-analyze useradd userdel groupdel; do
    command -v "$tool" >/dev/null || fail "$tool is not installed"
done
version=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml)
[ -n "$version" ] || fail "no version in Cargo.toml's [workspace.package]"
amd64=target/debian/deard_${version}-1_amd64.deb
arm64=target/debian/deard_${version}-1_arm64.deb
for deb in "$amd64" "$arm64"; do
    [ -f "$deb" ] || fail "$deb missing: run scripts/build-deb.sh first"
done
unit_src=daemon/systemd/deard.service

# --- 1. both packages, as files --------------------------------------------------------------
# What each package must hold (besides directories and copyright).
expected_files=(
    ./usr/bin/deard ./usr/bin/dear
    ./usr/lib/systemd/system/deard.service
    ./etc/deard/deard.toml.example
    ./usr/share/deard/models/edge/model.json ./usr/share/deard/models/edge/flow.onnx
    ./usr/share/deard/models/edge/fuse.onnx ./usr/share/deard/models/edge/refine.onnx
    ./usr/share/deard/samples/demo/capture.json
    ./usr/share/doc/deard/README.md ./usr/share/doc/deard/deard.example.toml
)
files_of() { dpkg-deb -c "$1" | awk '$1 !~ /^d/ {print $6}' | sort; }
scratch=$(mktemp -d /tmp/deard-test-deb.XXXXXX)
chmod 755 "$scratch"
for deb in "$amd64" "$arm64"; do
    arch=$(dpkg-deb -f "$deb" Architecture)
    step "$deb: $arch, $(du -h "$deb" | cut -f1), $(dpkg-deb -f "$deb" Installed-Size) KiB installed"
    [ "$(dpkg-deb -f "$deb" Package)" = deard ] || fail "$deb is not the package deard"
    case "$deb" in *_"$arch".deb) ;; *) fail "$deb says Architecture: $arch" ;; esac
    depends=$(dpkg-deb -f "$deb" Depends)
    for dep in libc6 passwd init-system-helpers; do
        grep -q "\b$dep\b" <<<"$depends" || fail "$deb does not depend on $dep: $depends"
    done
    files_of "$deb" >"$scratch/files-$arch"
    for f in "${expected_files[@]}"; do
        grep -qx "$f" "$scratch/files-$arch" || fail "$deb lacks $f"
    done
    frames=$(grep -c '^\./usr/share/deard/samples/demo/frames/.*\.png$' "$scratch/files-$arch" || true)
    want=$(find samples/demo/frames -name '*.png' | wc -l)
    [ "$frames" = "$want" ] || fail "$deb holds $frames frame files of samples/demo, not $want"
    dpkg-deb -I "$deb" conffiles | grep -qx /etc/deard/deard.toml.example \
        || fail "$deb does not mark /etc/deard/deard.toml.example as a conffile"
done
diff "$scratch/files-amd64" "$scratch/files-arm64" \
    || fail "the amd64 and arm64 packages hold different files (above)"

# The ELF machine of the arm64 package's programs (e_machine at byte 18: 183 is AArch64).
dpkg-deb -x "$arm64" "$scratch/arm64"
for bin in deard dear; do
    machine=$(od -An -tu2 -j18 -N2 "$scratch/arm64/usr/bin/$bin" | tr -d ' ')
    [ "$machine" = 183 ] || fail "usr/bin/$bin of $arm64 is not an aarch64 program (e_machine $machine)"
done
if command -v qemu-aarch64 >/dev/null && [ -d /usr/aarch64-linux-gnu/lib ]; then
    # Its deard, under qemu-user, reads the packaged example with the packaged paths (the
    # bundle and capture are checked at start-up, not by --print-config).
    printed=$(qemu-aarch64 -L /usr/aarch64-linux-gnu "$scratch/arm64/usr/bin/deard" \
        --config "$scratch/arm64/etc/deard/deard.toml.example" --print-config) \
        || fail "the arm64 deard (qemu-aarch64) cannot read the packaged example: $printed"
    grep -q '^bundle = "/usr/share/deard/models/edge"$' <<<"$printed" \
        || fail "the arm64 deard's effective configuration has not the packaged bundle: $printed"
    echo "arm64 deard under qemu-aarch64: $(qemu-aarch64 -L /usr/aarch64-linux-gnu \
        "$scratch/arm64/usr/bin/deard" --version), reads the packaged example"
else
    echo "arm64 deard not run: qemu-aarch64 or /usr/aarch64-linux-gnu missing (scripts/setup.sh --aarch64)"
fi

# --- 2. install the amd64 package ------------------------------------------------------------
dpkg -s deard >/dev/null 2>&1 && fail "the package deard is installed here; not touching it"
getent passwd deard >/dev/null && fail "user deard exists: deard looks installed here"
getent group dear >/dev/null && fail "group dear exists: deard looks installed here"
[ ! -e /run/deard ] || fail "/run/deard exists: a deard service looks present here"
[ ! -e /etc/deard ] || fail "/etc/deard exists: deard looks installed here"
[ ! -e /var/lib/deard ] || fail "/var/lib/deard exists: deard looks installed here"
app_user=dear-test-pkg-app
getent passwd "$app_user" >/dev/null && fail "user $app_user exists (a previous run's?): userdel it"

daemon_pid=
cleanup() {
    local rc=$?
    if [ -n "$daemon_pid" ]; then
        kill -KILL "$daemon_pid" 2>/dev/null || true
        wait "$daemon_pid" 2>/dev/null || true
    fi
    if dpkg -s deard >/dev/null 2>&1; then dpkg --purge deard >/dev/null 2>&1 || true; fi
    rm -rf /run/deard /etc/deard /var/lib/deard
    remove_accounts dear "$app_user" deard
    if [ "$rc" = 0 ]; then
        rm -rf "$scratch"
        echo "test-deb: ok"
    else
        echo "test-deb: logs kept in $scratch" >&2
    fi
    exit "$rc"
}
trap cleanup EXIT

step "dpkg -i $amd64"
dpkg -i "$amd64" >"$scratch/dpkg-install.log" 2>&1 \
    || fail "dpkg -i failed: $(cat "$scratch/dpkg-install.log")"
for f in "${expected_files[@]}"; do
    [ -e "${f#.}" ] || fail "${f#.} not installed"
done
for bin in /usr/bin/deard /usr/bin/dear; do
    [ -x "$bin" ] || fail "$bin is not executable"
done
echo "installed: $(/usr/bin/deard --version), $(dpkg -L deard | wc -l) paths"
dpkg-query -W -f='${Conffiles}\n' deard | grep -q '^ /etc/deard/deard.toml.example ' \
    || fail "dpkg does not list /etc/deard/deard.toml.example as a conffile of deard"

unit=/usr/lib/systemd/system/deard.service
diff <(sed 's|/usr/local/|/usr/|g' "$unit_src") "$unit" \
    || fail "$unit is not $unit_src with /usr/local/ read as /usr/ (above)"
verify=$(systemd-analyze verify "$unit" 2>&1) || true
if grep -i deard <<<"$verify"; then
    fail "systemd-analyze verify reports problems with the installed unit (above)"
fi
echo "unit: $unit_src with /usr/local/ -> /usr/, systemd-analyze verify: no complaints"

user_entry=$(getent passwd deard) || fail "postinst did not add the user deard"
IFS=: read -r _ _ uid gid _ home shell <<<"$user_entry"
[ "$(getent group dear | cut -d: -f3)" = "$gid" ] \
    || fail "deard's primary group is not dear: $user_entry / $(getent group dear)"
[ "$uid" -lt 1000 ] || fail "deard (uid $uid) is not a system user"
[ "$shell" = /usr/sbin/nologin ] || fail "deard's shell is $shell, not /usr/sbin/nologin"
[ ! -e "$home" ] || fail "deard's home $home exists"
echo "user: $user_entry"

wants=/etc/systemd/system/multi-user.target.wants/deard.service
# deb-systemd-helper links /lib/systemd/system/...: the same file where /lib is /usr/lib.
if [ ! -L "$wants" ] || [ "$(readlink -f "$wants")" != "$(readlink -f "$unit")" ]; then
    fail "the unit is not enabled: $wants -> '$(readlink "$wants")', not $unit"
fi
grep -qx 'ConditionPathExists=/etc/deard/deard.toml' "$unit" \
    || fail "the unit has no ConditionPathExists=/etc/deard/deard.toml"
[ ! -e /etc/deard/deard.toml ] || fail "the package installed /etc/deard/deard.toml"
echo "enabled ($wants), not started: /etc/deard/deard.toml absent (ConditionPathExists=)"

# --- 3. configure, run as the unit would, receive -------------------------------------------
step "configure: cp /etc/deard/deard.toml.example /etc/deard/deard.toml"
# The README's line, as written.
configure=$(grep -m1 '^sudo cp /etc/deard/deard.toml.example /etc/deard/deard.toml$' README.md) \
    || fail "README does not say 'sudo cp /etc/deard/deard.toml.example /etc/deard/deard.toml'"
${configure#sudo }

unit_value() { sed -n "s/^$1=//p" "$unit" | paste -sd ' '; }
exec_start=$(unit_value ExecStart)
user=$(unit_value User)
group=$(unit_value Group)
supplementary=$(unit_value SupplementaryGroups)
environment=$(unit_value Environment)
runtime_dir=/run/$(unit_value RuntimeDirectory)
runtime_mode=$(unit_value RuntimeDirectoryMode)
state=$(unit_value StateDirectory)
state_mode=$(unit_value StateDirectoryMode)
[ "$user:$group" = deard:dear ] || fail "the unit runs as $user:$group, not deard:dear"
# What systemd does for RuntimeDirectory= and StateDirectory=.
install -d -m "${runtime_mode:-0755}" -o "$user" -g "$group" "$runtime_dir"
if [ -n "$state" ]; then
    install -d -m "${state_mode:-0755}" -o "$user" -g "$group" "/var/lib/$state"
fi
groups_arg=()
if [ -n "$supplementary" ]; then groups_arg=(--groups "$(tr ' ' ',' <<<"$supplementary")"); fi
step "ExecStart=$exec_start as $user:$group, $environment"
# shellcheck disable=SC2086 # ExecStart= and Environment= are word lists, split as systemd does
(cd / && exec setpriv --reuid "$user" --regid "$group" "${groups_arg[@]}" \
    env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin $environment $exec_start) \
    >"$scratch/deard.log" 2>&1 &
daemon_pid=$!
wait_for_serving "$daemon_pid" "$scratch/deard.log" 60 "the installed deard"
pgrep -u "$user" -x deard >/dev/null || fail "no deard process of user $user"

client_root=${environment#*DEAR_IOX2_ROOT=}
client_root=${client_root%% *}
[ "$client_root" != "$environment" ] || fail "the unit sets no DEAR_IOX2_ROOT: $environment"
useradd --no-create-home --shell /usr/sbin/nologin "$app_user"
usermod -aG dear "$app_user"
install -d -o "$app_user" "$scratch/app"
as_app() {
    (cd / && env -i PATH=/usr/bin:/bin DEAR_IOX2_ROOT="$client_root" \
        setpriv --reuid "$app_user" --regid "$app_user" --init-groups /usr/bin/dear "$@")
}
step "dear list and dear dump as $app_user (in group dear), DEAR_IOX2_ROOT=$client_root"
listing=$(as_app list 2>&1) || fail "dear list failed: $listing"
grep -q '^ *dear/cam0/frames ' <<<"$listing" || fail "dear list does not show dear/cam0/frames: $listing"
as_app dump --count 5 --timeout-s 60 --out "$scratch/app/dump" >"$scratch/dump.log" 2>&1 \
    || fail "dear dump got no frames: $(cat "$scratch/dump.log" "$scratch/deard.log")"
n=$(find "$scratch/app/dump/frames" -name '*.depth.png' | wc -l)
[ "$n" = 5 ] || fail "dear dump wrote $n depth frames, not 5"
echo "$app_user received 5 frames from the installed deard ($(tail -1 "$scratch/dump.log"))"

step "SIGTERM"
kill -TERM "$(pgrep -u "$user" -x deard)"
rc=0
wait "$daemon_pid" || rc=$?
daemon_pid=
[ "$rc" = 0 ] || fail "the installed deard exited $rc on SIGTERM: $(tail -20 "$scratch/deard.log")"
grep -q stopped "$scratch/deard.log" || fail "no 'stopped' in the log: $(tail -5 "$scratch/deard.log")"

# --- 4. purge -------------------------------------------------------------------------------
step "dpkg --purge deard"
dpkg --purge deard >"$scratch/dpkg-purge.log" 2>&1 \
    || fail "dpkg --purge failed: $(cat "$scratch/dpkg-purge.log")"
for p in /usr/bin/deard /usr/bin/dear /usr/share/deard /usr/share/doc/deard /etc/deard "$unit" \
        "$wants" /run/deard /var/lib/deard; do
    if [ -e "$p" ] || [ -L "$p" ]; then fail "$p is left after dpkg --purge"; fi
done
getent passwd deard >/dev/null || fail "the purge removed the user deard (Debian keeps system users)"
echo "purged: files, configuration, enablement, /run/deard and /var/lib/deard gone; user deard and group dear kept"
