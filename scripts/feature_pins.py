"""Checks that feature-pins/ still gives the SDK's builds the workspace's feature sets.

Cargo compiles a dependency once per feature set. The C SDK (`cargo build -p dear-client-c`)
and the Python package (`maturin ... -m client-py/Cargo.toml`) are built on their own, so
without the pins a few low-level crates got smaller feature sets than in `cargo test
--workspace` and the daemon's build, and iceoryx2's whole stack was compiled again for each.
This script compares, for every third-party crate those builds share with the workspace's
build, its features in the target's context and in the host's (build scripts and procedural
macros, which cargo resolves apart), and names every crate whose sets differ: add it to
feature-pins/Cargo.toml with the workspace's features.

Usage: `python3 scripts/feature_pins.py` from the repository root (standard library and
`cargo tree` only); exits 1 when a build of the list below would compile a shared crate again.
"""

from __future__ import annotations

import subprocess
import sys
from collections import defaultdict

#: The builds scripts/test.sh and the packaging make apart from the workspace's.
SEPARATE_BUILDS = {
    "the C SDK (-p dear-client-c)": ["-p", "dear-client-c"],
    "the Python package (-p dear-client-py)": ["-p", "dear-client-py"],
}
#: What they should share artifacts with: `cargo test --workspace` (dev-dependencies included).
WORKSPACE = ["--workspace"]

Features = dict[str, set[str]]


def tree(packages: list[str], edges: str) -> Features:
    """`{"name version": {feature list, ...}}` of the third-party crates `cargo tree` shows."""
    command = ["cargo", "tree", *packages, "-e", edges, "--prefix", "none", "--no-dedupe"]
    out = subprocess.run(
        [*command, "-f", "{p}|{f}"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    crates: Features = defaultdict(set)
    for line in out.splitlines():
        line = line.removesuffix(" (*)")
        if "|" not in line:
            continue
        package, features = line.split("|", 1)
        fields = package.split()
        if len(fields) > 2 and fields[2].startswith("("):
            continue  # a workspace member (path dependency): its own features are its business
        crates[f"{fields[0]} {fields[1]}"].add(features.strip())
    return crates


def contexts(packages: list[str], dev: bool) -> tuple[Features, Features]:
    """(target, host) feature sets: `no-proc-macro` over normal edges leaves only crates built
    for the target; what the full tree adds beyond them is built for the host."""
    dev_edges = ",dev" if dev else ""
    target = tree(packages, f"normal{dev_edges},no-proc-macro")
    full = tree(packages, f"normal,build{dev_edges}")
    host = {name: sets - target.get(name, set()) for name, sets in full.items()}
    return target, {name: sets for name, sets in host.items() if sets}


def differences(build: tuple[Features, Features], ws: tuple[Features, Features]) -> list[str]:
    found = []
    for context, mine, theirs in (("target", build[0], ws[0]), ("host", build[1], ws[1])):
        for name, sets in mine.items():
            # A crate whose host and target features are equal appears once in the
            # workspace's tree, as a target crate; compare against that then.
            other = theirs.get(name) or ws[0].get(name)
            if other is not None and not sets <= other:
                found.append(f"{name} ({context}): {sorted(sets)} here, {sorted(other)} there")
    return found


def main() -> int:
    ws = contexts(WORKSPACE, dev=True)
    failed = False
    for label, packages in SEPARATE_BUILDS.items():
        found = differences(contexts(packages, dev=False), ws)
        if found:
            failed = True
            print(f"feature_pins: {label} builds these crates with other features than the")
            print("workspace (pin the workspace's features in feature-pins/Cargo.toml):")
            for line in found:
                print(f"  {line}")
        else:
            print(f"feature_pins: {label} shares every dependency's features with the workspace")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
