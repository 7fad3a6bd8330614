#!/usr/bin/env bash
# Builds the Python client package (`pip install dear-client`, `import dear`; client-py/) as
# wheels for CPython 3.11, the Python of Debian 12 and Raspberry Pi OS (bookworm):
#
#   scripts/build-wheels.sh            x86_64 and aarch64
#   scripts/build-wheels.sh x86_64     one of them
#   scripts/build-wheels.sh aarch64
#
# The wheels land in target/wheels/ (the file names and sizes are printed). Each is tagged with
# the manylinux level that maturin reads off the extension's glibc symbol versions (glibc 2.34
# for this build: Debian 12, Ubuntu 22.04 and newer; not older distributions) and carries no
# shared library besides the extension: it links only glibc and libgcc_s, which every manylinux
# policy allows. The aarch64 wheel is cross-built with Debian's cross gcc in target/aarch64, as
# the board tier builds the daemon; maturin supplies the target interpreter's settings for
# CPython on aarch64 Linux.
# Needs: scripts/setup.sh --aarch64 for aarch64, and the .venv that scripts/setup.sh makes
# (maturin is installed into it when missing).
set -euo pipefail
cd "$(dirname "$0")/.."
SCRIPT_NAME=build-wheels
. scripts/lib.sh

python=python3.11
maturin_version=1.16.0
out=target/wheels
case "${1:-all}" in
    all) arches=(x86_64 aarch64) ;;
    x86_64 | aarch64) arches=("$1") ;;
    *) fail "unknown architecture $1 (expected x86_64, aarch64 or nothing for both)" ;;
esac

[ -x .venv/bin/python ] || fail ".venv is missing: run scripts/setup.sh first"
if ! .venv/bin/maturin --version 2>/dev/null | grep -q " $maturin_version\$"; then
    .venv/bin/pip install --quiet "maturin==$maturin_version"
fi
mkdir -p "$out"
for arch in "${arches[@]}"; do
    # Only this build's wheel is listed, whatever older ones lie beside it.
    rm -f "$out"/dear_client-*_"$arch".whl
    t=$(now)
    case $arch in
        x86_64)
            .venv/bin/maturin build --quiet --release -i "$python" -m client-py/Cargo.toml \
                --out "$out" ;;
        aarch64)
            rustup target list --installed | grep -qx aarch64-unknown-linux-gnu \
                || fail "the Rust target aarch64-unknown-linux-gnu is not installed (scripts/setup.sh --aarch64)"
            command -v aarch64-linux-gnu-gcc >/dev/null \
                || fail "aarch64-linux-gnu-gcc is not installed (scripts/setup.sh --aarch64)"
            CARGO_TARGET_DIR=${DEAR_AARCH64_TARGET_DIR:-target/aarch64} \
                .venv/bin/maturin build --quiet --release --target aarch64-unknown-linux-gnu \
                -i "$python" -m client-py/Cargo.toml --out "$out" ;;
    esac
    wheel=$(ls "$out"/dear_client-*_"$arch".whl 2>/dev/null) \
        || fail "maturin wrote no $arch wheel into $out"
    printf '%s  %s KiB  (%s s)\n' "$wheel" "$(($(stat -c %s "$wheel") / 1024))" "$(since "$t")"
done
