#!/usr/bin/env bash
# Installs what the project needs on a fresh Debian/Ubuntu machine: Rust lint components (when
# missing), system packages, and the Python virtual environment of train/ (.venv). Idempotent:
# a second run only checks.
set -euo pipefail
cd "$(dirname "$0")/.."

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

# System packages: a C toolchain for -sys crates, pkg-config, Python's venv module.
missing=()
for pkg in build-essential pkg-config python3-venv; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing ${missing[*]}"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}"
fi

# Python environment for train/ (re-installed only when train/pyproject.toml changes).
if [ -d train ]; then
    stamp=.venv/.dear-train-installed
    want=$(sha256sum train/pyproject.toml | cut -d' ' -f1)
    if [ ! -x .venv/bin/python ]; then
        python3 -m venv .venv
    fi
    if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
        echo "setup: installing the train/ package and its pinned dependencies into .venv"
        .venv/bin/pip install --quiet --upgrade pip
        .venv/bin/pip install --quiet -e 'train[dev]'
        echo "$want" > "$stamp"
    fi
fi
