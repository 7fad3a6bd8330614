#!/usr/bin/env bash
# Tests the workspace as 64-bit ARM binaries (aarch64-unknown-linux-gnu), cross-built here and
# run under qemu-user (issue 18): what a Raspberry Pi 4/5, Jetson or i.MX 8 board would run.
#
# 1. Cross-build, release: deard and dear, chain_depth (tools/), and the unit tests of
#    dear-pipeline (geometry, the classical filter, calibration, the online estimator, the
#    bundle format: every test of its library). The two cargo invocations select packages so
#    that every dependency gets the same features in both (dear-pipeline's dev-dependencies
#    through one of its examples in the first): tract and the rest are compiled once, not once
#    per invocation (which took a third of the build).
# 2. Those unit tests under qemu-aarch64.
# 3. The shipped bundle (models/edge) through tract on aarch64: chain_depth runs the paper's
#    chain on frames of samples/demo natively and under qemu; the depth must agree within
#    1 mm on every pixel (tract's ARM kernels against the x86 ones). Prints the largest
#    difference.
# 4. One daemon + client exchange over real shared memory: the aarch64 deard replays
#    samples/demo with models/edge, the aarch64 `dear list` sees its service and the aarch64
#    `dear dump` receives 5 frames; SIGTERM stops the daemon with exit status 0.
#
# Release rather than debug: under qemu the optimised code runs the tests several times
# faster, the dependencies (tract, iceoryx2: most of the build) are built optimised by both
# profiles anyway, and scripts/build-deb.sh arm64 packages the same release binaries.
# Timings are printed; they are qemu's on this machine, not a board's.
#
# The aarch64 build has a target directory of its own, target/aarch64 (or
# $DEAR_AARCH64_TARGET_DIR), so it neither rebuilds nor locks target/; the native chain_depth
# builds in target/release with the features of the release deard and dear (nothing else is
# rebuilt there). Needs: scripts/setup.sh --aarch64.
#
#   scripts/test-aarch64.sh               all of the above
#   scripts/test-aarch64.sh --build-only  only the aarch64 deard and dear (scripts/build-deb.sh)
set -euo pipefail
cd "$(dirname "$0")/.."

SCRIPT_NAME=test-aarch64
. scripts/lib.sh

triple=aarch64-unknown-linux-gnu
sysroot=/usr/aarch64-linux-gnu
a64_target_dir=${DEAR_AARCH64_TARGET_DIR:-target/aarch64}
a64=$a64_target_dir/$triple/release
qemu=(qemu-aarch64 -L "$sysroot")
frames=${DEAR_AARCH64_FRAMES:-3}
build_only=false
case "${1:-}" in
    "") ;;
    --build-only) build_only=true ;;
    *) fail "unknown option $1 (expected --build-only or nothing)" ;;
esac

rustup target list --installed | grep -qx "$triple" \
    || fail "the Rust target $triple is not installed (scripts/setup.sh --aarch64)"
command -v aarch64-linux-gnu-gcc >/dev/null \
    || fail "aarch64-linux-gnu-gcc (the cross linker) is not installed (scripts/setup.sh --aarch64)"
command -v qemu-aarch64 >/dev/null \
    || fail "qemu-aarch64 is not installed (qemu-user; scripts/setup.sh --aarch64)"
[ -e "$sysroot/lib/ld-linux-aarch64.so.1" ] \
    || fail "$sysroot/lib/ld-linux-aarch64.so.1 missing (libc6-dev-arm64-cross; scripts/setup.sh --aarch64)"

a64_cargo() { CARGO_TARGET_DIR=$a64_target_dir cargo "$@" --release --target "$triple"; }

# --- 1. cross-build -------------------------------------------------------------------------
step "cross-build for $triple in $a64_target_dir (release): deard, dear, chain_depth, dear-pipeline's unit tests"
t=$(now)
a64_cargo build --quiet -p deard -p dear-cli -p dear-tools -p dear-pipeline \
    --bin deard --bin dear --bin chain_depth --example write_geometry_fixtures
if $build_only; then
    echo "cross-build: $(since "$t") s"
    exit 0
fi
# The library's test executable (the same packages' libraries, for the same features).
mkdir -p "$a64_target_dir"
a64_cargo test --quiet --no-run --message-format=json \
    -p dear-pipeline -p deard -p dear-cli -p dear-tools --lib \
    >"$a64_target_dir/test-build.json" 2>"$a64_target_dir/test-build.log" \
    || fail "building the unit tests for $triple failed: $(cat "$a64_target_dir/test-build.log")"
unit_tests=$(python3 -c '
import json, sys
for line in open(sys.argv[1]):
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "dear_pipeline" \
            and m["profile"]["test"] and m.get("executable"):
        print(m["executable"])
' "$a64_target_dir/test-build.json")
[ -x "$unit_tests" ] || fail "no dear-pipeline unit test executable in $a64_target_dir/test-build.json"
echo "cross-build: $(since "$t") s"
for bin in deard dear chain_depth; do
    machine=$(od -An -tu2 -j18 -N2 "$a64/$bin" | tr -d ' ')
    [ "$machine" = 183 ] || fail "$a64/$bin is not an aarch64 executable (ELF machine $machine)"
done

# --- 2. unit tests under qemu ---------------------------------------------------------------
step "dear-pipeline unit tests under qemu-aarch64 ($unit_tests)"
t=$(now)
log=$a64_target_dir/unit-tests.log
# From the package's directory, as cargo test runs them.
(cd pipeline && "${qemu[@]}" "$unit_tests") >"$log" 2>&1 \
    || fail "dear-pipeline's unit tests failed under qemu: $(grep -E '^test .*FAILED|panicked|^error' "$log" | head -20) (log: $log)"
grep '^test result:' "$log"
grep -q '^test result: ok\. [1-9][0-9]* passed; 0 failed' "$log" \
    || fail "dear-pipeline's unit tests did not pass under qemu (log: $log)"
for module in geometry filter; do
    n=$(grep -c "^test $module::.* \.\.\. ok$" "$log" || true)
    [ "$n" -gt 0 ] || fail "no $module:: test passed under qemu (log: $log)"
    echo "$module: $n tests passed"
done
echo "unit tests under qemu: $(since "$t") s"

# --- 3. the bundle through tract: aarch64 against x86 ---------------------------------------
scratch=$(mktemp -d /tmp/dear-aarch64.XXXXXX)
root=$(mktemp -d /dev/shm/dear-aarch64-iox2.XXXXXX)
daemon_pid=
cleanup() {
    local rc=$?
    if [ -n "$daemon_pid" ]; then kill -KILL "$daemon_pid" 2>/dev/null || true; wait "$daemon_pid" 2>/dev/null || true; fi
    rm -rf "$root"
    if [ "$rc" = 0 ]; then rm -rf "$scratch"; else echo "test-aarch64: logs kept in $scratch" >&2; fi
    exit "$rc"
}
trap cleanup EXIT

step "models/edge on $frames frames of samples/demo: x86-64 native against aarch64 under qemu"
cargo build --release --quiet -p deard -p dear-cli -p dear-tools \
    --bin deard --bin dear --bin chain_depth
native=target/release/chain_depth
chain_args=(run --bundle models/edge --capture samples/demo --frames "$frames")
t=$(now)
"$native" "${chain_args[@]}" --out "$scratch/x86_64.depth" | sed 's/^/x86-64: /'
echo "x86-64 native: $(since "$t") s"
t=$(now)
"${qemu[@]}" "$a64/chain_depth" "${chain_args[@]}" --out "$scratch/aarch64.depth" \
    | sed 's/^/aarch64 (qemu): /'
echo "aarch64 under qemu: $(since "$t") s"
"$native" compare "$scratch/x86_64.depth" "$scratch/aarch64.depth" --tolerance-mm 1 \
    || fail "the aarch64 depth differs from the x86-64 depth by more than 1 mm (above)"

# --- 4. daemon and clients over shared memory -----------------------------------------------
step "aarch64 deard replaying samples/demo, aarch64 dear list / dear dump (DEAR_IOX2_ROOT=$root)"
export DEAR_IOX2_ROOT=$root
service=dear/aarch64/frames
t=$(now)
"${qemu[@]}" "$a64/deard" --replay samples/demo --service "$service" --loop --stats-interval 5 \
    >"$scratch/deard.log" 2>&1 &
daemon_pid=$!
wait_for_serving "$daemon_pid" "$scratch/deard.log" 120 "the aarch64 deard"
echo "deard serving after $(since "$t") s"
listing=$("${qemu[@]}" "$a64/dear" list 2>&1) || fail "the aarch64 dear list failed: $listing"
grep -q "^ *$service " <<<"$listing" || fail "the aarch64 dear list does not show $service: $listing"
t=$(now)
"${qemu[@]}" "$a64/dear" dump --service "$service" --count 5 --timeout-s 120 --out "$scratch/dump" \
    >"$scratch/dump.log" 2>&1 \
    || fail "the aarch64 dear dump received no frames: $(cat "$scratch/dump.log" "$scratch/deard.log")"
n=$(find "$scratch/dump/frames" -name '*.depth.png' | wc -l)
[ "$n" = 5 ] || fail "the aarch64 dear dump wrote $n depth frames, not 5"
echo "dear dump: 5 frames in $(since "$t") ($(tail -1 "$scratch/dump.log"))"
kill -TERM "$daemon_pid"
rc=0
wait "$daemon_pid" || rc=$?
daemon_pid=
[ "$rc" = 0 ] || fail "the aarch64 deard exited $rc on SIGTERM: $(tail -20 "$scratch/deard.log")"
grep -q stopped "$scratch/deard.log" || fail "no 'stopped' in the aarch64 deard's log"
grep -E 'fps|frames' "$scratch/deard.log" | tail -2 | sed 's/^/deard: /'
echo "test-aarch64: ok (timings under qemu-user on this machine, not a board's)"
