#!/usr/bin/env bash
# Dropped frames of a paced replay with the defaults: deard replays CAPTURE PASSES times over
# (a capture of PASSES copies of its frames, hard links with their timestamps continued, so the
# pacing runs unbroken across passes) with `--pacing timestamps` and everything else default,
# exits at the end, and the counts of its last log line are printed.
#
#   scripts/replay_drops.sh CAPTURE [PASSES]     # PASSES default 10
#
# e.g. the 30 fps 640×480 figure of docs/performance.md:
#   target/release/dear-synth sequence --frames 300 --width 640 --height 480 --seed 5 --out /tmp/vga300
#   scripts/replay_drops.sh /tmp/vga300 10        # 3,000 frames, 100 s
#
# Other settings (e.g. [capture] queue_depth) go in a config file: CONFIG=file; DEARD=path runs
# another build of the daemon (a before/after comparison on the same machine and load).
# Writes out/replay-drops-deard.log; the looped capture is made once in ${CAPTURE}-x${PASSES}.
set -euo pipefail
cd "$(dirname "$0")/.."

capture=${1:?usage: scripts/replay_drops.sh CAPTURE [PASSES]}
passes=${2:-10}
looped="${capture%/}-x${passes}"
deard=${DEARD:-target/release/deard}
[ -x "$deard" ] || cargo build --release -p deard
mkdir -p out
log=out/replay-drops-deard.log

if [ ! -f "$looped/capture.json" ]; then
    python3 - "$capture" "$looped" "$passes" <<'EOF'
import json, os, sys
src, dst, passes = sys.argv[1], sys.argv[2], int(sys.argv[3])
m = json.load(open(os.path.join(src, "capture.json")))
frames = m["frames"]
period = (frames[-1]["timestamp_ns"] - frames[0]["timestamp_ns"]) // max(len(frames) - 1, 1)
span = frames[-1]["timestamp_ns"] - frames[0]["timestamp_ns"] + period
os.makedirs(os.path.join(dst, "frames"), exist_ok=True)
out = []
for k in range(passes):
    for i, f in enumerate(frames):
        new_id = k * len(frames) + i
        for kind in ("rgb", "amp", "depth"):
            a = os.path.join(src, "frames", f"{f['id']:06d}.{kind}.png")
            b = os.path.join(dst, "frames", f"{new_id:06d}.{kind}.png")
            if not os.path.exists(b):
                os.link(a, b)
        out.append(dict(f, id=new_id, timestamp_ns=f["timestamp_ns"] + k * span))
m["frames"] = out
m["source"] = {"kind": f"{passes} passes of a capture, hard links", "original": os.path.abspath(src)}
json.dump(m, open(os.path.join(dst, "capture.json"), "w"))
print(f"replay_drops.sh: {dst}: {len(out)} frames ({passes} passes of {len(frames)})")
EOF
fi

config_flag=()
[ -n "${CONFIG:-}" ] && config_flag=(--config "$CONFIG")
start=$(date +%s.%N)
"$deard" "${config_flag[@]}" --replay "$looped" --pacing timestamps --exit-when-done \
    --camera "drops-$$" >"$log" 2>&1
end=$(date +%s.%N)
# The last line ("stopped") has the totals; strip the log's colour codes first.
totals=$(sed 's/\x1b\[[0-9;]*m//g' "$log" | grep 'stopped' | tail -1 |
    grep -o '\(published\|skipped\|dropped\)=[0-9]*' | tr '\n' ' ')
late=$(sed 's/\x1b\[[0-9;]*m//g' "$log" | { grep -o 'late_frames=[0-9]*' || true; } | awk -F= '{ n += $2 } END { print n + 0 }')
echo "replay_drops.sh: $deard, $looped in $(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.0f", b - a }') s, load $(cut -d' ' -f1-3 /proc/loadavg): $totals late=$late (handed on >10 ms after due)"
echo "daemon log: $log"
