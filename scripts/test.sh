#!/usr/bin/env bash
# Runs every test of the project (what CI runs): lints, Rust unit and end-to-end tests, Python
# tests. Installs what it needs first (scripts/setup.sh).
set -euo pipefail
cd "$(dirname "$0")/.."

# The time of each tier, printed at the end, whether the run passes or fails (then the tier
# that failed is marked). `tier NAME` ends the running tier and starts NAME.
tier_names=()
tier_seconds=()
tier_name=""
tier_start=$SECONDS
tier() {
    if [ -n "$tier_name" ]; then
        tier_names+=("$tier_name")
        tier_seconds+=($((SECONDS - tier_start)))
    fi
    tier_name=$1
    tier_start=$SECONDS
    [ -z "$1" ] || echo "== $1"
}
print_tier_times() {
    local rc=$? i
    local last=$tier_name
    tier ""
    echo "== time per tier (s)"
    for i in "${!tier_names[@]}"; do
        if [ "$rc" != 0 ] && [ "${tier_names[$i]}" = "$last" ]; then
            printf '%6d  %s (FAILED)\n' "${tier_seconds[$i]}" "${tier_names[$i]}"
        else
            printf '%6d  %s\n' "${tier_seconds[$i]}" "${tier_names[$i]}"
        fi
    done
    printf '%6d  total\n' "$SECONDS"
    exit "$rc"
}
trap print_tier_times EXIT

tier "setup (scripts/setup.sh)"
scripts/setup.sh
# A run from a clean clone gains nothing from incremental state, and it is gigabytes.
export CARGO_INCREMENTAL=0
# A full disk shows up as a linker "Bus error" far from its cause; say up front what there is.
df -h . | sed 's/^/disk: /'

tier "msrv";         python3 scripts/msrv.py
tier "cargo fmt";    cargo fmt --all --check
tier "cargo clippy"; cargo clippy --workspace --all-targets --quiet -- -D warnings
tier "cargo test";   cargo test --workspace
# The SDK stays thin: an app linking dear-client gets the protocol and iceoryx2, not the
# pipeline, tract or the CLI's crates (issue 15).
tier "thin SDK"
if cargo tree -p dear-client -e normal --prefix none | grep -E '^(tract|clap|indicatif|dear-pipeline) '; then
    echo "dear-client pulls the crates above; the SDK must not" >&2
    exit 1
fi
# The runtime carries no evaluation harness (issues 17, 36): deard does not depend on the
# dear-eval crate.
if cargo tree -p deard -e normal --prefix none | grep -E '^dear-eval '; then
    echo "deard's build includes dear-eval, the evaluation; it must not" >&2
    exit 1
fi
# The SDK's separate builds (the C library, the Python wheels) share the workspace's compiled
# dependencies (feature-pins/): a crate they would build with other features is named here.
python3 scripts/feature_pins.py
# The instruction sets a board or an older PC runs (issue 36): dear-pipeline's unit tests under
# qemu-x86_64 emulating an AVX2 CPU and one without AVX, so the versions this AVX-512 machine
# never dispatches to are tested too (about 25 s).
tier "CPU levels (scripts/test-cpu-levels.sh)"; scripts/test-cpu-levels.sh

if [ -d train ]; then
    # Two commands, not `a && b`: errexit ignores a failure on the left of `&&`.
    tier "ruff";   .venv/bin/ruff check train scripts fixtures tests/scripts client-py
    .venv/bin/ruff format --check train scripts fixtures tests/scripts client-py
    tier "pytest"; (cd train && ../.venv/bin/python -m pytest -q tests)
    # The outside aligner's scoring against the shared fixtures (numpy only, no OpenCV).
    tier "outside aligner scoring"; .venv/bin/python scripts/outside_aligner.py --check
    # The ROS 2 bridge (issue 35) against an independent DDS: Cyclone DDS's Python package
    # subscribes to dear-ros2's topics with the ROS 2 type names, and the depth it receives
    # equals `dear dump`'s; CameraInfo and PointCloud2 checked too (loopback unicast; ~5 s).
    # Built with the feature set of `cargo test --workspace` above (every package selected,
    # dev-dependencies too: --tests), so only the binary itself is compiled; `-p dear-ros2`
    # alone resolved smaller feature sets and compiled 29 dependencies again (5 minutes of CI).
    tier "ROS 2 bridge (tests/scripts/ros2_bridge.py)"
    cargo build --quiet --workspace --tests --bin dear-ros2
    .venv/bin/python tests/scripts/ros2_bridge.py
    # The Python client package against a real target/debug/deard (built by cargo test above).
    tier "pytest (client-py)"; (cd client-py && ../.venv/bin/python -m pytest -q tests)
    # `dear view` in a real browser (issue 35): Debian's Chromium, through chromedriver, loads
    # the page served from a deard stream and checks that its pictures change with the stream
    # (the debug binaries of cargo test above; a few seconds).
    tier "browser view (tests/scripts/view_browser.py)"
    .venv/bin/python tests/scripts/view_browser.py
fi

# The install tier: the README's install recipe and the hardened systemd unit, on this machine
# (needs root: it adds the deard user and installs into /usr/local and /etc, then removes it
# all; and release binaries, about 8 minutes to build on 2 cores).
if [ "$(id -u)" = 0 ]; then
    tier "install recipe and unit (scripts/install_test.sh)"
    cargo build --release --quiet -p deard -p dear-cli
    # On its own: built with the CLI, the SDK in libdear_client.a would get the CLI's features
    # (images: the pipeline and tract).
    cargo build --release --quiet -p dear-client-c
    scripts/install_test.sh
else
    echo "== install recipe and unit: skipped (needs root; run sudo scripts/install_test.sh)"
fi

# The live-capture tier (issue 14): the kernel's own V4L2 — vivid in a qemu VM (TCG, no KVM;
# the kernel package is cached under ~/.cache/dear/v4l2-vm) — first the driver alone, then
# deard capturing vivid nodes (depth, RGB, amplitude) with a client checking the depth it
# receives, through a device loss, and from a replay of its recording. About a minute warm,
# plus the release build of the three binaries.
tier "V4L2 in a VM (scripts/test-v4l2-vm.sh --self-test, --deard)"
cargo build --release --quiet -p deard -p dear-cli -p dear-tools \
    --bin deard --bin dear --bin dear-v4l-check
for mode in self-test deard; do
    if ! scripts/test-v4l2-vm.sh "--$mode" > "target/v4l2-vm-$mode.log" 2>&1; then
        tail -n 80 "target/v4l2-vm-$mode.log"
        echo "test-v4l2-vm.sh --$mode failed (whole console: target/v4l2-vm-$mode.log)" >&2
        exit 1
    fi
    grep -E '^(ok|FAILED|self-test|deard-live|test-v4l2-vm):' "target/v4l2-vm-$mode.log" || true
done

# The board tier (issue 18): the workspace cross-built for aarch64 (64-bit ARM boards) and
# tested under qemu-user — dear-pipeline's unit tests, the shipped bundle's depth against
# x86-64's, a daemon + client exchange over shared memory — then the Debian packages for amd64
# and arm64 (the arm64 one from the same release build in target/aarch64), installed, run and
# purged here when root. About 14 minutes on 2 cores, 12 of them the cold aarch64 build.
tier "aarch64 under emulation (scripts/test-aarch64.sh)"
scripts/test-aarch64.sh
# The Python wheels (issue 35): CPython 3.11 wheels for x86_64 and aarch64, each installed by pip
# into a fresh place and receiving frames from a real deard of its architecture, equal to `dear
# dump`'s (aarch64 under qemu-user: the board tier's binaries and Debian's arm64 python3.11);
# about 3 minutes, most of it the two release builds of the extension.
tier "Python wheels (scripts/test-wheels.sh)"
scripts/test-wheels.sh
tier "Debian packages (scripts/build-deb.sh)"
scripts/build-deb.sh
if [ "$(id -u)" = 0 ]; then
    tier "Debian packages installed and run (scripts/test-deb.sh)"
    scripts/test-deb.sh
else
    echo "== Debian packages installed and run: skipped (needs root; run sudo scripts/test-deb.sh)"
fi
