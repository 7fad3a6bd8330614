#!/usr/bin/env bash
# Builds the Debian package `deard` (daemon, `dear` CLI, the edge bundle, the sample capture,
# the example configuration and the systemd unit) with cargo-deb, for amd64 (this machine)
# and/or arm64 (cross-built), into target/debian/. The package's metadata is in
# daemon/Cargo.toml ([package.metadata.deb]), its maintainer scripts in packaging/debian/.
#
#   scripts/build-deb.sh            both
#   scripts/build-deb.sh amd64      only amd64 (target/release)
#   scripts/build-deb.sh arm64      only arm64 (cross-built in target/aarch64, or
#                                   $DEAR_AARCH64_TARGET_DIR: the native target/ stays unlocked)
#
# Needs cargo-deb 3 and, for arm64, the cross tools: scripts/setup.sh --aarch64 installs them.
# The unit is daemon/systemd/deard.service, the one the README's recipe installs, with
# /usr/local/ read as /usr/ (the package's binaries and data live under /usr); written to
# target/packaging/systemd/ for cargo-deb.
set -euo pipefail
cd "$(dirname "$0")/.."

fail() { echo "build-deb: $*" >&2; exit 1; }

arches=()
case "${1:-all}" in
    all) arches=(amd64 arm64) ;;
    amd64 | arm64) arches=("$1") ;;
    *) fail "unknown architecture '$1' (expected amd64, arm64 or nothing for both)" ;;
esac
[ $# -le 1 ] || fail "one argument at most (amd64, arm64), got: $*"

cargo deb --version 2>/dev/null | grep -q '^cargo-deb 3\.' \
    || fail "cargo-deb 3 is not installed (scripts/setup.sh --aarch64 installs it)"
triple=aarch64-unknown-linux-gnu
a64_target_dir=${DEAR_AARCH64_TARGET_DIR:-target/aarch64}
if [[ " ${arches[*]} " == *" arm64 "* ]]; then
    rustup target list --installed | grep -qx "$triple" \
        || fail "the Rust target $triple is not installed (scripts/setup.sh --aarch64)"
    command -v aarch64-linux-gnu-gcc >/dev/null \
        || fail "aarch64-linux-gnu-gcc (the cross linker) is not installed (scripts/setup.sh --aarch64)"
fi

# The unit, one definition: the recipe's, with the installed paths of the package.
unit_dir=target/packaging/systemd
mkdir -p "$unit_dir"
sed 's|/usr/local/|/usr/|g' daemon/systemd/deard.service >"$unit_dir/deard.service"
grep -q '^ExecStart=/usr/bin/deard --config /etc/deard/deard.toml$' "$unit_dir/deard.service" \
    || fail "daemon/systemd/deard.service: ExecStart= is not '/usr/local/bin/deard --config /etc/deard/deard.toml'; the package's unit is derived from it"
if grep -n '/usr/local' "$unit_dir/deard.service"; then
    fail "the package's unit still names /usr/local (above)"
fi

out=target/debian
mkdir -p "$out"
for arch in "${arches[@]}"; do
    start=$(date +%s)
    case "$arch" in
        amd64)
            echo "build-deb: cargo build --release (deard, dear)"
            cargo build --release --quiet -p deard -p dear-cli --bin deard --bin dear
            deb=$(cargo deb -p deard --no-build --strip --quiet -o "$out")
            ;;
        arm64)
            # The build scripts/test-aarch64.sh tests (the same invocation, so nothing is built
            # twice when both run).
            echo "build-deb: scripts/test-aarch64.sh --build-only (deard, dear for $triple in $a64_target_dir)"
            DEAR_AARCH64_TARGET_DIR=$a64_target_dir scripts/test-aarch64.sh --build-only
            deb=$(CARGO_TARGET_DIR=$a64_target_dir \
                cargo deb -p deard --no-build --strip --quiet --target "$triple" -o "$out")
            ;;
    esac
    [ -f "$deb" ] || fail "cargo deb printed '$deb', which is not a file"
    echo "build-deb: $deb ($(du -h "$deb" | cut -f1), $(dpkg-deb -f "$deb" Installed-Size) KiB installed, $(( $(date +%s) - start )) s)"
done
