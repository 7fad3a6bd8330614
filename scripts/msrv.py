"""Checks that the workspace's declared `rust-version` is honest.

The declared minimum supported Rust version must be at least the highest `rust-version` of
every crate a build or a test of the workspace compiles, as Cargo.lock pins them: the
workspace members' normal, build and dev dependencies, and the normal and build dependencies
of those, recursively. (Our own code's use of newer standard-library APIs is clippy's
`incompatible_msrv` lint, which reads the same declared version.)

Usage: `python3 scripts/msrv.py` from the repository root; exits 1 and names the crates that
need more when the declaration is too low. Only the standard library is used, so it runs
before any virtual environment exists.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import tomllib


def version_key(v: str) -> tuple[int, int, int]:
    """`1.85` and `1.85.0` are the same version."""
    parts = [int(part) for part in v.split(".")] + [0, 0]
    return (parts[0], parts[1], parts[2])


def host_triple() -> str:
    out = subprocess.run(["rustc", "-vV"], check=True, capture_output=True, text=True).stdout
    return next(line.split(": ", 1)[1] for line in out.splitlines() if line.startswith("host: "))


def compiled_packages(metadata: dict) -> set[str]:
    """Package ids that building or testing the workspace members compiles."""
    nodes = {n["id"]: n for n in metadata["resolve"]["nodes"]}
    members = set(metadata["workspace_members"])
    seen: set[str] = set()
    stack = list(members)
    while stack:
        pid = stack.pop()
        if pid in seen:
            continue
        seen.add(pid)
        for dep in nodes[pid]["deps"]:
            kinds = {k["kind"] for k in dep["dep_kinds"]}
            # Dev-dependencies are compiled only for the workspace's own tests.
            if pid in members or kinds - {"dev"}:
                stack.append(dep["pkg"])
    return seen


def main() -> int:
    root = Path(__file__).resolve().parent.parent
    declared = tomllib.loads((root / "Cargo.toml").read_text())["workspace"]["package"][
        "rust-version"
    ]
    out = subprocess.run(
        # Dependencies of other platforms (wasm, Windows) are never compiled here.
        [
            *("cargo", "metadata", "--format-version", "1", "--locked"),
            *("--filter-platform", host_triple()),
        ],
        cwd=root,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    metadata = json.loads(out)
    packages = {p["id"]: p for p in metadata["packages"]}
    needs = [
        (packages[pid]["rust_version"], packages[pid]["name"], packages[pid]["version"])
        for pid in compiled_packages(metadata)
        if packages[pid].get("rust_version")
    ]
    required = max((v for v, _, _ in needs), key=version_key, default="1.0")
    if version_key(declared) < version_key(required):
        above = sorted(
            {
                f"{name} {ver} (rust-version {v})"
                for v, name, ver in needs
                if version_key(v) > version_key(declared)
            }
        )
        print(
            f"Cargo.toml: workspace rust-version {declared} is below {required}, which these "
            f"locked dependencies require: " + "; ".join(above),
            file=sys.stderr,
        )
        return 1
    print(f"rust-version {declared}: every compiled crate needs at most {required}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
