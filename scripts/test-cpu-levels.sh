#!/usr/bin/env bash
# Runs dear-pipeline's unit tests on the CPUs the daemon meets without the widest instruction
# sets (issue 36): the hot loops are compiled for AVX-512, AVX2 and the x86-64 baseline and
# pick one at run time (pipeline/src/simd.rs), so a machine with AVX-512 only ever tests the
# first. Under qemu-user's emulated CPUs the same test binary runs
#
#   Haswell-noTSX   AVX2 + FMA, no AVX-512  → the second version
#   Nehalem         SSE4.2, no AVX          → the baseline a board without AVX2 runs
#
# and DEAR_EXPECT_SIMD makes simd's own test fail if the emulated CPU dispatched elsewhere.
# About 15 s per CPU on 2 cores, after the debug build `cargo test --workspace` already made:
# the binary is that build's (asked for with the same package set, so nothing is rebuilt; with
# `-p dear-pipeline` alone cargo unifies features differently and rebuilt much of the
# dependency tree, 5 of this tier's 5.5 minutes on a clean clone).
set -euo pipefail
cd "$(dirname "$0")/.."
SCRIPT_NAME=test-cpu-levels
. scripts/lib.sh

command -v qemu-x86_64 >/dev/null || fail "qemu-x86_64 not found (scripts/setup.sh installs qemu-user)"
bin=$(cargo test --workspace --no-run --message-format=json 2>/dev/null |
    python3 -c 'import json, sys
for line in sys.stdin:
    d = json.loads(line)
    if (d.get("reason") == "compiler-artifact" and d.get("executable")
            and d["target"]["name"] == "dear_pipeline" and d["target"]["kind"] == ["lib"]):
        print(d["executable"])')
[ -x "$bin" ] || fail "no unit-test binary of dear-pipeline from cargo test --no-run"
cd pipeline  # as cargo test runs it: fixtures are found relative to the crate
for tier in Haswell-noTSX:avx2 Nehalem:baseline; do
    cpu=${tier%%:*} level=${tier#*:}
    t0=$(now)
    DEAR_EXPECT_SIMD=$level qemu-x86_64 -cpu "$cpu" "$bin" --test-threads 2 -q > "../target/cpu-level-$level.log" 2>&1 ||
        { tail -n 40 "../target/cpu-level-$level.log"; fail "unit tests on $cpu ($level)"; }
    echo "$SCRIPT_NAME: $cpu ($level): $(grep -E '^test result' "../target/cpu-level-$level.log") in $(since "$t0") s"
done
