#!/usr/bin/env bash
# Tests the Python wheels (scripts/build-wheels.sh) as a user gets them: each is installed by pip
# into a fresh place with nothing of the checkout on its path, receives frames from a real deard
# of its architecture over shared memory, and the frames it received must equal, plane for
# plane, what `dear dump` (the Rust SDK) wrote for the same samples.
#
# - x86_64: a fresh venv of this machine's python3.11; pip takes numpy from the package index.
# - aarch64: Debian's arm64 CPython 3.11 (python3.11-minimal and its libraries, fetched with apt
#   into target/wheel-test/arm64-python without touching the system's apt configuration), run
#   under qemu-user; pip installs the wheel and numpy's aarch64 wheel into a fresh directory for
#   that interpreter; the daemon and `dear dump` are the aarch64 builds of the board tier
#   (scripts/test-aarch64.sh), also under qemu.
#
#   scripts/test-wheels.sh            both (builds the wheels first)
#   scripts/test-wheels.sh x86_64     one of them
set -euo pipefail
cd "$(dirname "$0")/.."
SCRIPT_NAME=test-wheels
. scripts/lib.sh

case "${1:-all}" in
    all) arches=(x86_64 aarch64) ;;
    x86_64 | aarch64) arches=("$1") ;;
    *) fail "unknown architecture $1 (expected x86_64, aarch64 or nothing for both)" ;;
esac
scripts/build-wheels.sh "${1:-all}"

scratch=$(mktemp -d /tmp/dear-wheels.XXXXXX)
export DEAR_IOX2_ROOT
DEAR_IOX2_ROOT=$(mktemp -d /dev/shm/dear-wheels-iox2.XXXXXX)
daemon_pid=
cleanup() {
    local rc=$?
    if [ -n "$daemon_pid" ]; then
        kill -KILL "$daemon_pid" 2>/dev/null || true
        wait "$daemon_pid" 2>/dev/null || true
    fi
    rm -rf "$DEAR_IOX2_ROOT"
    if [ "$rc" = 0 ]; then rm -rf "$scratch"; else echo "test-wheels: logs kept in $scratch" >&2; fi
    exit "$rc"
}
trap cleanup EXIT

# Debian's arm64 CPython 3.11, unpacked (not installed) from the same release as this machine,
# into $arm64_root.
arm64_root=target/wheel-test/arm64-python
fetch_arm64_python() {
    local root=$arm64_root apt_dir=target/wheel-test/apt debs
    if [ ! -x "$root/usr/bin/python3.11" ]; then
        step "fetching Debian's arm64 python3.11 into $root"
        rm -rf "$root" "$apt_dir"
        mkdir -p "$apt_dir/lists/partial" "$apt_dir/cache/archives/partial" "$apt_dir/debs" "$root"
        touch "$apt_dir/status"
        local apt=(apt-get -qq -o APT::Architecture=arm64 -o APT::Architectures::=arm64
            -o "Dir::State::Lists=$apt_dir/lists" -o "Dir::Cache=$apt_dir/cache"
            -o "Dir::State::status=$apt_dir/status" -o Debug::NoLocking=1)
        "${apt[@]}" update || fail "apt-get update for arm64 failed (Debian's mirror reachable?)"
        (cd "$apt_dir/debs" && "${apt[@]}" download python3.11-minimal libpython3.11-minimal \
            libpython3.11-stdlib libc6 libgcc-s1 libstdc++6 zlib1g libexpat1 libffi8 2>&1 | grep -v unsandboxed || true)
        debs=("$apt_dir"/debs/*.deb)
        [ "${#debs[@]}" = 9 ] || fail "fetched ${#debs[@]} of 9 arm64 packages into $apt_dir/debs"
        for deb in "${debs[@]}"; do dpkg-deb -x "$deb" "$root"; done
        rm -rf "$apt_dir"
    fi
}

# run_client ARCH PYTHON... : deard of ARCH replaying samples/demo, the wheel's client and
# `dear dump` at once, then the comparison.
run_client() {
    local arch=$1 deard=$2 dear=$3
    shift 3
    local service=dear/wheel-$arch/frames out=$scratch/$arch
    local runner=()
    [ "$arch" = aarch64 ] && runner=(qemu-aarch64 -L /usr/aarch64-linux-gnu)
    mkdir -p "$out"
    "${runner[@]}" "$deard" --replay samples/demo --loop --refine none --service "$service" \
        >"$out/deard.log" 2>&1 &
    daemon_pid=$!
    wait_for_serving "$daemon_pid" "$out/deard.log" 120 "the $arch deard"
    "$@" tests/scripts/wheel_client.py receive "$service" "$out/received" --timeout-s 300 \
        >"$out/client.log" 2>&1 &
    local client_pid=$!
    wait_for_line "$client_pid" "$out/client.log" '^receiving' 120 "the $arch wheel's client"
    "${runner[@]}" "$dear" dump --service "$service" --count 3 --timeout-s 120 --out "$out/dump" \
        >"$out/dump.log" 2>&1 || fail "the $arch dear dump failed: $(cat "$out/dump.log")"
    touch "$out/received/stop"
    wait "$client_pid" || fail "the $arch wheel's client failed: $(cat "$out/client.log")"
    sed "s/^/$arch client: /" "$out/client.log"
    kill -TERM "$daemon_pid"
    wait "$daemon_pid" || fail "the $arch deard exited $? on SIGTERM: $(tail -20 "$out/deard.log")"
    daemon_pid=
    .venv/bin/python tests/scripts/wheel_client.py compare "$out/received" "$out/dump" \
        | sed "s/^/$arch: /"
}

for arch in "${arches[@]}"; do
    wheel=$(ls target/wheels/dear_client-*_"$arch".whl)
    case $arch in
        x86_64)
            step "x86_64: $wheel into a fresh venv"
            python3.11 -m venv "$scratch/venv"
            "$scratch/venv/bin/pip" install --quiet "$wheel"
            # The install tier's release build, by the same command (nothing rebuilt in
            # scripts/test.sh; a debug build of these two packages alone would unify features
            # differently and rebuild much of the tree).
            cargo build --release --quiet -p deard -p dear-cli
            run_client x86_64 target/release/deard target/release/dear \
                "$scratch/venv/bin/python" ;;
        aarch64)
            fetch_arm64_python
            step "aarch64: $wheel for Debian's arm64 python3.11 under qemu-user"
            # pip of this machine resolves and unpacks for the other platform (wheels only);
            # each manylinux level the board's glibc (2.36) runs is named, as pip does not
            # widen a --platform to the older levels (numpy's aarch64 wheels are 2_28).
            .venv/bin/pip install --quiet --target "$scratch/arm64-site" --only-binary=:all: \
                --platform manylinux_2_34_aarch64 --platform manylinux_2_28_aarch64 \
                --platform manylinux_2_17_aarch64 --python-version 3.11 --implementation cp \
                --abi cp311 "$wheel"
            a64=${DEAR_AARCH64_TARGET_DIR:-target/aarch64}/aarch64-unknown-linux-gnu/release
            [ -x "$a64/deard" ] && [ -x "$a64/dear" ] \
                || fail "$a64/deard or dear missing: scripts/test-aarch64.sh --build-only builds them"
            run_client aarch64 "$a64/deard" "$a64/dear" \
                env PYTHONPATH="$scratch/arm64-site" PYTHONNOUSERSITE=1 \
                qemu-aarch64 -L "$arm64_root" "$arm64_root/usr/bin/python3.11" ;;
    esac
done
echo "test-wheels: ok"
