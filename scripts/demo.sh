#!/usr/bin/env bash
# The main job: deard replays the bundled sample capture and a client shows what arrives.
# Writes a few received frames (with colourised depth and RGB blends) to out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh --rust-only
cargo build --release --quiet -p deard -p dear-cli

capture=${DEAR_DEMO_CAPTURE:-samples/demo}
service=dear/demo/frames
if [ ! -f "$capture/capture.json" ]; then
    echo "demo: $capture/capture.json not found (the sample capture ships with the repository)" >&2
    exit 1
fi
rm -rf out/demo && mkdir -p out
target/release/deard --replay "$capture" --service "$service" --loop --stats-interval 2 2> out/deard.log &
daemon=$!
trap 'kill -TERM $daemon 2>/dev/null; wait $daemon 2>/dev/null || true' EXIT

echo "== dear watch (10 s): what the client receives"
target/release/dear watch --service "$service" --count-seconds 10
echo "== dear dump: 3 frames with previews to out/demo"
target/release/dear dump --service "$service" --count 3 --out out/demo --preview
ls out/demo/previews
echo "== daemon log (last lines)"
tail -n 5 out/deard.log
