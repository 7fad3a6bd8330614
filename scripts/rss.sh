#!/usr/bin/env bash
# Resident memory of deard over a long replay: runs the release daemon on a capture in a loop
# as fast as it can process (default: samples/demo with the default DEAR engine), samples its
# VmRSS every few seconds, and stops once it has published FRAMES frames.
#
#   scripts/rss.sh [FRAMES]          # default 10000; CAPTURE=dir to replay another capture
#
# Writes out/rss.csv (seconds, published, rss_mib) and prints the resident memory after
# warm-up (the first sample past 300 published frames), the largest and the last.
set -euo pipefail
cd "$(dirname "$0")/.."

frames=${1:-10000}
capture=${CAPTURE:-samples/demo}
interval=${INTERVAL:-5}
[ -x target/release/deard ] || cargo build --release -p deard
mkdir -p out
log=out/rss-deard.log
csv=out/rss.csv

target/release/deard --replay "$capture" --loop --pacing fast --stats-interval "$interval" \
    --camera "rss-$$" >"$log" 2>&1 &
pid=$!
trap 'kill "$pid" 2>/dev/null || true' EXIT

echo "seconds,published,rss_mib" >"$csv"
start=$(date +%s)
published=0
while kill -0 "$pid" 2>/dev/null; do
    sleep "$interval"
    rss_kib=$(awk '/^VmRSS:/ {print $2}' "/proc/$pid/status" 2>/dev/null || echo 0)
    # The stats lines end with published=N; strip the log's colour codes first.
    last=$(sed 's/\x1b\[[0-9;]*m//g' "$log" | grep -o 'published=[0-9]*' | tail -1 || true)
    published=${last#published=}
    published=${published:-0}
    awk -v s="$(($(date +%s) - start))" -v p="$published" -v k="$rss_kib" \
        'BEGIN { printf "%d,%d,%.1f\n", s, p, k / 1024 }' >>"$csv"
    if [ "$published" -ge "$frames" ]; then
        break
    fi
done
if ! kill -0 "$pid" 2>/dev/null; then
    echo "rss.sh: deard exited early; its log is $log" >&2
    tail -5 "$log" >&2
    exit 1
fi
kill -INT "$pid"
wait "$pid" || true
trap - EXIT

awk -F, 'NR > 1 {
        if (!warm && $2 >= 300) { warm = $3; warm_at = $2 }
        if ($3 > max) max = $3
        last = $3; last_at = $2; secs = $1
    }
    END {
        printf "deard RSS: %.1f MiB after warm-up (%d frames), max %.1f MiB, %.1f MiB at %d frames (%d s)\n",
            warm, warm_at, max, last, last_at, secs
    }' "$csv"
echo "samples: $csv, daemon log: $log"
