#!/usr/bin/env bash
# Soak test of deard: a real release daemon replays a capture in a loop while two real clients
# subscribe over iceoryx2 shared memory, one that keeps up and one that holds every sample for
# --hold-ms (a slow application); stops once the daemon has published --frames frames (or,
# with --until input, once it has taken --frames input frames: published + skipped + dropped,
# which is how long a replay at the capture's own pace lasts).
#
#   scripts/soak.sh [--frames N] [--until published|input] [--engine classical|dear]
#                   [--capture DIR] [--pacing fast|timestamps] [--out DIR] [--hold-ms MS]
#                   [--deard BIN] [--client BIN] [--stall-s S]
#
#   defaults: --frames 100000 --until published --engine classical --capture samples/demo
#             --pacing fast --out out/soak/<engine>-<frames> --hold-ms 200 --stall-s 120
#             --deard target/release/deard
#             --client target/release/soak_client
#               (cargo build --release -p dear-tools --bin soak_client)
#
# About every second it records (OUT/timeseries.csv): the daemon's resident memory (VmRSS, and its
# anonymous and shared-memory parts, from /proc/PID/status), the shared memory the daemon has
# mapped (the /dev/shm files in /proc/PID/maps: allocated kB by `du`, since iceoryx2's data
# segment is a sparse file far larger than what is touched, and apparent kB), the daemon's
# published / skipped / dropped counters (its --stats-interval 1 log line), each client's
# received and lost frames (their progress lines) and resident memory, and the 1-minute load
# average (the machine is shared; every figure needs it beside it).
#
# At the end: a fresh client must receive frames (the daemon is still serving); the daemon is
# frozen (SIGSTOP) so the clients can drain and stop against a fixed published count; then it
# is stopped with SIGTERM. OUT/summary.json and OUT/summary.txt (one screen) hold the verdict:
# RSS growth from the first minute to the end (a leak check), the clients' loss and latency
# percentiles (publish-to-receive and the header's Total stage), and the daemon's counters.
# The daemon and client logs and reports stay in OUT. Exit status 0 when the soak ran to the
# end and the daemon was still serving; 1 otherwise (the summary says why).
set -euo pipefail

repo=$(cd "$(dirname "$0")/.." && pwd)

usage() {
    sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"
}

die() {
    echo "soak.sh: $*" >&2
    exit 2
}

frames=100000
until=published
engine=classical
capture=$repo/samples/demo
pacing=fast
out=
hold_ms=200
deard=$repo/target/release/deard
client=$repo/target/release/soak_client
stall_s=120

while [ $# -gt 0 ]; do
    case $1 in
    --frames | --until | --engine | --capture | --pacing | --out | --hold-ms | --deard | --client | --stall-s)
        [ $# -ge 2 ] || die "$1 needs a value"
        case $1 in
        --frames) frames=$2 ;;
        --until) until=$2 ;;
        --engine) engine=$2 ;;
        --capture) capture=$2 ;;
        --pacing) pacing=$2 ;;
        --out) out=$2 ;;
        --hold-ms) hold_ms=$2 ;;
        --deard) deard=$2 ;;
        --client) client=$2 ;;
        --stall-s) stall_s=$2 ;;
        esac
        shift 2
        ;;
    -h | --help)
        usage
        exit 0
        ;;
    *) die "unknown argument $1 (see --help)" ;;
    esac
done

# Validate everything before starting a process, so a typo fails in a second, not after an
# hour's soak.
is_count() { [[ $1 =~ ^[0-9]+$ ]] && [ "$1" -gt 0 ]; }
is_count "$frames" || die "--frames must be a positive integer, not '$frames'"
[[ $hold_ms =~ ^[0-9]+$ ]] || die "--hold-ms must be a non-negative integer, not '$hold_ms'"
is_count "$stall_s" || die "--stall-s must be a positive integer, not '$stall_s'"
case $until in published | input) ;; *) die "--until must be published or input, not '$until'" ;; esac
case $engine in classical | dear) ;; *) die "--engine must be classical or dear, not '$engine'" ;; esac
case $pacing in fast | timestamps) ;; *) die "--pacing must be fast or timestamps, not '$pacing'" ;; esac
[ -f "$capture/capture.json" ] || die "--capture $capture has no capture.json"
[ -x "$deard" ] || die "deard not found at $deard (cargo build --release -p deard, or --deard)"
[ -x "$client" ] ||
    die "soak_client not found at $client (cargo build --release -p dear-tools --bin soak_client, or --client)"
command -v python3 >/dev/null || die "python3 is needed for the summary"
capture=$(cd "$capture" && pwd)
out=${out:-$repo/out/soak/$engine-$frames}
mkdir -p "$out" || die "cannot create --out $out"
out=$(cd "$out" && pwd)
# Only this script's own files are replaced: --out may name a directory with other things in it.
for f in timeseries.csv summary.json summary.txt deard.log client-{fast,slow,fresh}.{csv,log,json}; do
    rm -f "${out:?}/$f"
done

# Frames per replay pass (clients read frame_id wrap-arounds with it when the daemon stamps
# no sequence) and the recorded frame period (what --pacing timestamps replays at).
read -r loop_frames period_ms < <(python3 - "$capture/capture.json" <<'EOF'
import json, sys
frames = json.load(open(sys.argv[1]))["frames"]
ts = [f["timestamp_ns"] for f in frames]
period = (ts[-1] - ts[0]) / (len(ts) - 1) / 1e6 if len(ts) > 1 else 0.0
print(len(frames), f"{period:.3f}")
EOF
)
is_count "${loop_frames:-}" || die "cannot read the frame list of $capture/capture.json"

service=soak/$$/frames
daemon_log=$out/deard.log
csv=$out/timeseries.csv
daemon=
fast=
slow=

# Whatever happens, no process of this script outlives it (a frozen daemon included).
cleanup() {
    for pid in $fast $slow $daemon; do
        kill -TERM "$pid" 2>/dev/null || true
        kill -CONT "$pid" 2>/dev/null || true
    done
}
trap cleanup EXIT

kib() {
    if [ -n "$1" ] && [ -r "/proc/$1/status" ]; then
        awk -v k="$2" '$1 == k":" {v = $2} END {print v + 0}' "/proc/$1/status" 2>/dev/null || echo 0
    else
        echo 0
    fi
}
# The last progress line of a client: elapsed_s,received,lost,out_of_order,rejected,last_id.
progress() { tail -n 1 "$1" 2>/dev/null | awk -F, '$1 ~ /^[0-9.]+$/ {print $2 "," $3; ok=1} END {if (!ok) print "0,0"}'; }
# The daemon's newest published / skipped / dropped counters (colour codes stripped).
counters() {
    sed 's/\x1b\[[0-9;]*m//g' "$daemon_log" | grep -o 'published=[0-9]* skipped=[0-9]* dropped=[0-9]*' |
        tail -n 1 | sed 's/[a-z]*=//g; s/ /,/g' | grep . || echo 0,0,0
}
# Shared memory the daemon has mapped: the transport's files (under its root directory, see
# dear_proto::transport) named in its memory map, allocated and apparent kB, and how many.
transport_root=${DEAR_IOX2_ROOT:-/dev/shm/dear}
shm_usage() {
    local files
    files=$(awk -v root="${transport_root%/}/" 'index($6, root) == 1 {print $6}' "/proc/$1/maps" 2>/dev/null | sort -u)
    if [ -z "$files" ]; then
        echo 0,0,0
        return
    fi
    # A file can vanish between the map and du (a peer's segment removed): count what is left.
    local alloc apparent count
    alloc=$(echo "$files" | xargs du -k -c 2>/dev/null | awk '$2 == "total" {print $1}')
    apparent=$(echo "$files" | xargs du -k -c --apparent-size 2>/dev/null | awk '$2 == "total" {print $1}')
    count=$(echo "$files" | wc -l)
    echo "${alloc:-0},${apparent:-0},$count"
}

# Clients first, so both see the stream from its first frame (the service is open-or-create on
# either side) and the slow client's losses cover the whole run.
"$client" --service "$service" --name fast --loop-frames "$loop_frames" \
    --report "$out/client-fast.json" >"$out/client-fast.csv" 2>"$out/client-fast.log" &
fast=$!
"$client" --service "$service" --name slow --hold-ms "$hold_ms" --loop-frames "$loop_frames" \
    --report "$out/client-slow.json" >"$out/client-slow.csv" 2>"$out/client-slow.log" &
slow=$!
sleep 1
for pid in $fast $slow; do
    kill -0 "$pid" 2>/dev/null || die "a client exited at start; see $out/client-*.log"
done

# deard runs from the repository root: the default bundle path (models/edge) is relative.
(cd "$repo" && exec env NO_COLOR=1 "$deard" --replay "$capture" --loop --pacing "$pacing" \
    --refine "$engine" --stats-interval 1 --service "$service") >"$daemon_log" 2>&1 &
daemon=$!
start=$(date +%s.%N)

echo "t_s,load1,deard_alive,published,skipped,dropped,rss_kib,rss_anon_kib,rss_shmem_kib,shm_alloc_kib,shm_apparent_kib,shm_files,fast_received,fast_lost,slow_received,slow_lost,fast_rss_kib,slow_rss_kib" >"$csv"
echo "soak: deard pid $daemon on $service ($engine, $pacing, $(basename "$capture"): $loop_frames frames/pass, ${period_ms} ms recorded period), clients $fast (keeps up) and $slow (holds ${hold_ms} ms); until $frames $until; output $out"

published=0
last_change=$(date +%s)
last_published=0
ended=published
while true; do
    sleep 1
    alive=1
    kill -0 "$daemon" 2>/dev/null || alive=0
    t=$(awk -v s="$start" -v n="$(date +%s.%N)" 'BEGIN {printf "%.1f", n - s}')
    load1=$(cut -d' ' -f1 /proc/loadavg)
    IFS=, read -r published skipped dropped <<<"$(counters)"
    row="$t,$load1,$alive,$published,$skipped,$dropped"
    row="$row,$(kib "$daemon" VmRSS),$(kib "$daemon" RssAnon),$(kib "$daemon" RssShmem),$(shm_usage "$daemon")"
    row="$row,$(progress "$out/client-fast.csv"),$(progress "$out/client-slow.csv")"
    row="$row,$(kib "$fast" VmRSS),$(kib "$slow" VmRSS)"
    echo "$row" >>"$csv"
    if [ "$alive" = 0 ]; then
        ended="daemon-exited"
        break
    fi
    taken=$published
    [ "$until" = published ] || taken=$((published + skipped + dropped))
    if [ "$taken" -ge "$frames" ]; then
        break
    fi
    now=$(date +%s)
    if [ "$published" != "$last_published" ]; then
        last_published=$published
        last_change=$now
    elif [ $((now - last_change)) -ge "$stall_s" ]; then
        ended=stalled
        break
    fi
done

# Still serving? A new subscriber, after all that, must get frames within 15 s.
serving=false
if [ "$ended" = published ] &&
    timeout 15 "$client" --service "$service" --name fresh --loop-frames "$loop_frames" --frames 3 \
        --report "$out/client-fresh.json" >"$out/client-fresh.csv" 2>"$out/client-fresh.log"; then
    serving=true
fi

# Freeze the daemon so the published count is fixed while the clients drain their queues (the
# slow one holds each of at most 2 queued samples for hold_ms), then stop them and the daemon.
kill -STOP "$daemon" 2>/dev/null || true
sleep "$(awk -v h="$hold_ms" 'BEGIN {printf "%.1f", 3 * h / 1000 + 1}')"
for pid in $fast $slow; do
    kill -TERM "$pid" 2>/dev/null || true
done
clients_ok=true
for pid in $fast $slow; do
    wait "$pid" || clients_ok=false
done
fast=
slow=
kill -TERM "$daemon" 2>/dev/null || true
kill -CONT "$daemon" 2>/dev/null || true
daemon_exit=0
# SIGTERM must end the daemon promptly; give it 30 s, then say so and kill it.
for _ in $(seq 300); do
    kill -0 "$daemon" 2>/dev/null || break
    sleep 0.1
done
if kill -0 "$daemon" 2>/dev/null; then
    kill -KILL "$daemon" 2>/dev/null || true
    daemon_exit=killed
fi
if wait "$daemon" 2>/dev/null; then :; else
    rc=$?
    [ "$daemon_exit" = killed ] || daemon_exit=$rc
fi
daemon=
trap - EXIT

python3 - "$out" "$frames" "$until" "$engine" "$pacing" "$capture" "$hold_ms" "$loop_frames" "$period_ms" \
    "$ended" "$serving" "$clients_ok" "$daemon_exit" <<'EOF'
import csv, json, os, re, sys

(out, frames, until, engine, pacing, capture, hold_ms, loop_frames, period_ms, ended, serving,
 clients_ok, daemon_exit) = sys.argv[1:]
rows = list(csv.DictReader(open(os.path.join(out, "timeseries.csv"))))
num = lambda r, k: float(r[k] or 0)

def load(name):
    try:
        return json.load(open(os.path.join(out, f"client-{name}.json")))
    except (OSError, ValueError):
        return None

log = re.sub(r"\x1b\[[0-9;]*m", "", open(os.path.join(out, "deard.log")).read())
# The daemon's last line, "stopped published=… skipped=… dropped=… [other counters] uptime_s=…":
# every key=value number is kept, so counters added later come along.
stopped = [l for l in log.splitlines() if re.search(r"\bstopped\b.*\bpublished=\d", l)]
final = None
if stopped:
    final = {k: float(v) if "." in v else int(v)
             for k, v in re.findall(r"(\w+)=([0-9]+(?:\.[0-9]+)?)\b", stopped[-1])}
    if not {"published", "skipped", "dropped", "uptime_s"} <= final.keys():
        final = None
warnings = len(re.findall(r"\bWARN\b", log))
errors = len(re.findall(r"\bERROR\b", log))

# Leak check: VmRSS at the end (the median of the last tenth of the samples, so one
# allocator swing does not decide it) against VmRSS after the first minute (warm-up: allocator
# pools, the pipeline's buffers, the network worker, the shared-memory samples touched once).
# A run shorter than 4 minutes has no steady state to compare: it is reported, not judged.
alive_rows = [r for r in rows if r["deard_alive"] == "1" and num(r, "rss_kib") > 0]
rss = None
if alive_rows:
    duration = num(alive_rows[-1], "t_s")
    judged = duration >= 240
    base = next(r for r in alive_rows if num(r, "t_s") >= (60.0 if judged else duration / 4))
    tail = sorted(num(r, "rss_kib") for r in alive_rows[-max(1, len(alive_rows) // 10):])
    end_kib = tail[len(tail) // 2]
    rss = {
        "judged": judged,
        "baseline_at_s": num(base, "t_s"),
        "baseline_mib": num(base, "rss_kib") / 1024,
        "end_at_s": duration,
        "end_mib": end_kib / 1024,
        "last_mib": num(alive_rows[-1], "rss_kib") / 1024,
        "growth_mib": (end_kib - num(base, "rss_kib")) / 1024,
        "max_mib": max(num(r, "rss_kib") for r in alive_rows) / 1024,
        "anon_baseline_mib": num(base, "rss_anon_kib") / 1024,
        "anon_end_mib": num(alive_rows[-1], "rss_anon_kib") / 1024,
        "shmem_end_mib": num(alive_rows[-1], "rss_shmem_kib") / 1024,
    }
    rss["growth_pct"] = 100 * rss["growth_mib"] / rss["baseline_mib"] if rss["baseline_mib"] else None
shm = None
if alive_rows:
    shm = {
        "alloc_mib_max": max(num(r, "shm_alloc_kib") for r in alive_rows) / 1024,
        "alloc_mib_end": num(alive_rows[-1], "shm_alloc_kib") / 1024,
        "apparent_mib_end": num(alive_rows[-1], "shm_apparent_kib") / 1024,
        "files_end": int(num(alive_rows[-1], "shm_files")),
    }
loads = [num(r, "load1") for r in rows]
clients = {name: load(name) for name in ("fast", "slow", "fresh")}
# Frames the clients could not account for: what the daemon published (frozen while they
# drained; at most the one frame in flight is published after the final SIGTERM) against
# what each saw or counted as lost from its first frame on.
published_final = final["published"] if final else None
for c in (clients["fast"], clients["slow"]):
    if c and published_final is not None and c.get("received"):
        # The clients subscribed before the daemon started, so frames before the first one
        # received are its number (sequence or, on the first pass, frame_id) from 0.
        before = c["first_frame_id"] or 0
        c["published_minus_seen"] = published_final - c["received"] - c["lost"] - before

# A leak is growth that stays: more than 10 % and 20 MiB from the first minute to the end
# (the DEAR chain's allocator swings by about ±20 MiB at 320×240, scripts/rss.sh).
leak = bool(rss and rss["judged"] and rss["growth_mib"] > 20 and (rss["growth_pct"] or 0) > 10)
ok = ended == "published" and serving == "true" and clients_ok == "true" and daemon_exit == "0" and not leak
summary = {
    "verdict": "pass" if ok else "FAIL",
    "ended": ended,
    "still_serving": serving == "true",
    "clients_exited_cleanly": clients_ok == "true",
    "daemon_exit": daemon_exit,
    "rss_leak_suspected": leak if rss and rss["judged"] else None,
    "target_frames": int(frames),
    "target_counts": until,
    "engine": engine,
    "pacing": pacing,
    "capture": capture,
    "capture_frames_per_pass": int(loop_frames),
    "capture_period_ms": float(period_ms),
    "slow_client_hold_ms": int(hold_ms),
    "daemon_final": final,
    "daemon_fps": final["published"] / final["uptime_s"] if final and final["uptime_s"] else None,
    "daemon_log_warnings": warnings,
    "daemon_log_errors": errors,
    "rss": rss,
    "shared_memory": shm,
    "load1": {"min": min(loads), "median": sorted(loads)[len(loads) // 2], "max": max(loads)} if loads else None,
    "clients": clients,
}
json.dump(summary, open(os.path.join(out, "summary.json"), "w"), indent=2)

def pct(p):
    return "-" if not p else f"p50 {p['p50_ms']:.2f} / p95 {p['p95_ms']:.2f} / p99 {p['p99_ms']:.2f} / max {p['max_ms']:.2f} ms"

lines = [
    f"soak {summary['verdict']}: {engine}, {pacing} pacing, {os.path.basename(capture)} "
    f"({loop_frames} frames/pass, {float(period_ms):.1f} ms period), target {frames} {until} frames; ended: {ended}",
]
if final:
    others = "".join(f", {k} {v}" for k, v in final.items()
                     if k not in ("published", "skipped", "dropped", "uptime_s"))
    lines.append(f"daemon: published {final['published']}, skipped {final['skipped']}, dropped "
                 f"{final['dropped']}{others} in {final['uptime_s']:.0f} s ({summary['daemon_fps']:.1f} fps); "
                 f"exit {daemon_exit}; log: {warnings} warnings, {errors} errors")
if rss:
    verdict = ("YES" if leak else "no") if rss["judged"] else "not judged (run under 4 min)"
    lines.append(f"deard RSS: {rss['baseline_mib']:.1f} MiB at {rss['baseline_at_s']:.0f} s -> "
                 f"{rss['end_mib']:.1f} MiB at the end (median of the last tenth; {rss['growth_mib']:+.1f} MiB), "
                 f"max {rss['max_mib']:.1f}; anon {rss['anon_baseline_mib']:.1f} -> {rss['anon_end_mib']:.1f} MiB; "
                 f"leak suspected: {verdict}")
if shm:
    lines.append(f"shared memory mapped by deard: {shm['alloc_mib_end']:.1f} MiB allocated (max "
                 f"{shm['alloc_mib_max']:.1f}) of {shm['apparent_mib_end']:.0f} MiB apparent, {shm['files_end']} files")
for name in ("fast", "slow"):
    c = clients[name]
    if not c:
        lines.append(f"client {name}: no report")
        continue
    unseen = c.get("published_minus_seen")
    missed = c.get("daemon_missed_in_gaps") or 0
    lines.append(f"client {name} (hold {c['hold_ms']} ms): received {c['received']}, lost {c['lost']} "
                 f"({c['lost_method']}" + (f"; {missed} more never published: the daemon dropped or skipped them" if missed else "")
                 + f"), out of order {c['out_of_order']}, rejected {c['rejected']}"
                 + (f", published - seen {unseen}" if unseen is not None else ""))
    lines.append(f"  publish->receive {pct(c['publish_to_receive'])}")
    lines.append(f"  header total     {pct(c['daemon_total'])}")
lines.append(f"still serving (a new client got frames): {'yes' if serving == 'true' else 'NO'}")
if summary["load1"]:
    l = summary["load1"]
    lines.append(f"machine load (1-min average): min {l['min']:.2f}, median {l['median']:.2f}, max {l['max']:.2f} on {os.cpu_count()} CPUs")
lines.append(f"files: {out}/timeseries.csv, summary.json, deard.log, client-*.json")
open(os.path.join(out, "summary.txt"), "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
sys.exit(0 if ok else 1)
EOF
