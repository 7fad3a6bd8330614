#!/usr/bin/env bash
# Installs what the project needs on a fresh Debian/Ubuntu machine: Rust lint components (when
# missing), system packages, and the Python virtual environment of train/ (.venv). Idempotent:
# a second run only checks.
#
#   scripts/setup.sh              everything (what scripts/test.sh needs)
#   scripts/setup.sh --rust-only  only what building the Rust workspace needs (scripts/demo.sh):
#                                 no Python packages, no PyTorch
#   scripts/setup.sh --aarch64    the Rust workspace, plus cross-building for 64-bit ARM boards
#                                 and packaging (scripts/test-aarch64.sh, scripts/test-deb.sh):
#                                 the Rust target aarch64-unknown-linux-gnu, Debian's cross gcc
#                                 and arm64 C library, qemu-user, dpkg-dev and cargo-deb
#
# PyTorch: the CPU build (download.pytorch.org/whl/cpu, about 0.2 GB) unless DEAR_TORCH=cuda,
# which takes PyPI's default wheel with its CUDA libraries (about 6.8 GB). When the CPU index
# cannot be reached, PyPI's wheel is installed and the script says so.
set -euo pipefail
cd "$(dirname "$0")/.."

rust_only=false
aarch64=true
case "${1:-}" in
    "") ;;
    --rust-only) rust_only=true; aarch64=false ;;
    --aarch64) rust_only=true ;;
    *) echo "setup: unknown option $1 (expected --rust-only, --aarch64 or nothing)" >&2; exit 2 ;;
esac
# The cargo-deb release the packaging was written against (cargo install --locked builds it).
cargo_deb_version=3.8.0

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

if ! command -v cargo >/dev/null; then
    echo "setup: cargo not found. Install Rust (https://rustup.rs) and run again." >&2
    exit 1
fi
for component in rustfmt clippy; do
    if ! cargo "${component/rustfmt/fmt}" --version >/dev/null 2>&1; then
        rustup component add "$component"
    fi
done

# System packages: a C toolchain for -sys crates, pkg-config, libclang (the `v4l` crate's build
# generates its V4L2 bindings with bindgen; the kernel headers come with the C toolchain), and
# (for train/) Python's venv.
packages=(build-essential pkg-config libclang1)
# train/'s venv; strace for the install test (scripts/install_test.sh traces the daemon's system
# calls against the unit's filter) and the system python3's numpy (it runs a Python app as
# another user, who cannot reach the checkout's .venv).
$rust_only || packages+=(python3-venv strace python3-numpy)
# The browser test of `dear view` (tests/scripts/view_browser.py): Debian's Chromium and its
# chromedriver (about 350 MB installed).
$rust_only || packages+=(chromium chromium-driver)
# Cross-building for aarch64 (linker, the target's C library and headers for -sys crates),
# running its binaries here (qemu-user: qemu-aarch64 -L /usr/aarch64-linux-gnu), and building
# .deb packages (dpkg-dev: dpkg-shlibdeps for their dependencies; binutils for strip).
$aarch64 && packages+=(gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user dpkg-dev)
missing=()
for pkg in "${packages[@]}"; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing ${missing[*]}"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}"
fi

if $aarch64; then
    if ! rustup target list --installed | grep -qx aarch64-unknown-linux-gnu; then
        echo "setup: adding the Rust target aarch64-unknown-linux-gnu"
        rustup target add aarch64-unknown-linux-gnu
    fi
    if ! cargo deb --version 2>/dev/null | grep -q '^cargo-deb 3\.'; then
        echo "setup: installing cargo-deb $cargo_deb_version (cargo install, about a minute)"
        cargo install cargo-deb --locked --version "$cargo_deb_version" --quiet
    fi
fi

# PyPI's torch wheel for Linux x86_64 needs its CUDA libraries (nvidia-*-cu12 packages, about
# 6.8 GB installed) even to run on the CPU. Installed one package at a time and without pip's
# cache, the disk holds at most the installed set plus one wheel; all at once, pip first keeps
# every downloaded wheel (about 4 GB more) beside it, which is how a machine with 7 GB free ran
# out of space.
install_torch_from_pypi() {
    local torch=$1 need_gb=8 free_gb report requirement
    free_gb=$(df -P --block-size=1G .venv | awk 'NR == 2 { print $4 }')
    if [ "$free_gb" -lt "$need_gb" ]; then
        echo "setup: $torch from PyPI needs about $need_gb GB free on the file system of" \
             "$PWD/.venv; it has $free_gb GB. Free some space, or make" \
             "download.pytorch.org/whl/cpu reachable (the CPU build is about 0.7 GB)." >&2
        exit 1
    fi
    # pip resolves the whole set once from the index's metadata (no wheel is downloaded for a
    # dry run), then each resolved package is installed alone, exactly as resolved.
    report=.venv/.dear-torch-resolution.json
    .venv/bin/pip install --quiet --no-cache-dir --dry-run --ignore-installed \
        --report "$report" "$torch"
    .venv/bin/python -c '
import json, sys
for item in json.load(open(sys.argv[1]))["install"]:
    print(item["metadata"]["name"] + "==" + item["metadata"]["version"])
' "$report" > .venv/.dear-torch-requirements
    while read -r requirement; do
        .venv/bin/pip install --quiet --no-cache-dir --no-deps "$requirement"
    done < .venv/.dear-torch-requirements
}

# Python environment for train/ (re-installed only when train/pyproject.toml changes).
if ! $rust_only && [ -d train ]; then
    stamp=.venv/.dear-train-installed
    want=$(sha256sum train/pyproject.toml | cut -d' ' -f1)
    if [ ! -x .venv/bin/python ]; then
        python3 -m venv .venv
    fi
    if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
        echo "setup: installing the train/ package and its pinned dependencies into .venv"
        .venv/bin/pip install --quiet --upgrade pip
        torch=$(grep -o '"torch==[^"]*"' train/pyproject.toml | tr -d '"')
        if [ "${DEAR_TORCH:-cpu}" = cuda ]; then
            echo "setup: DEAR_TORCH=cuda: $torch from PyPI (with its CUDA libraries)"
        elif .venv/bin/pip install --quiet --timeout 20 --retries 1 \
                --index-url https://download.pytorch.org/whl/cpu "$torch" 2>/dev/null; then
            echo "setup: $torch, CPU build"
        else
            echo "setup: download.pytorch.org/whl/cpu cannot be reached: $torch from PyPI" \
                 "(its default wheel brings the CUDA libraries, about 6.8 GB installed)"
            install_torch_from_pypi "$torch"
        fi
        .venv/bin/pip install --quiet -e 'train[dev]'
        echo "$want" > "$stamp"
    fi
fi

# The Python client package `dear` (client-py/: PyO3 + maturin) in .venv, as an editable
# install whose extension module is built with the dev profile (dependencies at opt-level 3).
# Rebuilt only when its sources, the SDK's or the lock file change.
if ! $rust_only && [ -d client-py ]; then
    stamp=.venv/.dear-client-py-installed
    want=$({
        rustc -V
        find client-py/Cargo.toml client-py/pyproject.toml client-py/src client-py/python \
            client/Cargo.toml client/src proto/Cargo.toml proto/src Cargo.lock \
            -type f ! -name '*.so' ! -name '*.pyc' -print0 | sort -z | xargs -0 sha256sum
    } | sha256sum | cut -d' ' -f1)
    if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ] \
            || ! .venv/bin/python -c 'import dear' 2>/dev/null; then
        echo "setup: building the Python client package (client-py, import dear) into .venv"
        .venv/bin/pip install --quiet maturin==1.16.0
        VIRTUAL_ENV="$PWD/.venv" .venv/bin/maturin develop --quiet -m client-py/Cargo.toml
        echo "$want" > "$stamp"
    fi
fi
