#!/bin/sh
# Guest script of `scripts/test-v4l2-vm.sh --deard` (busybox sh, vivid n_devs=3
# node_types=0x101,0x101,0x1): deard captures a live "module" made of two vivid instances and a
# client receives exactly the depth that was fed in; then the nodes vanish (vivid unbound)
# and come back (bound again), and deard must report the loss, keep serving and resume.
# deard records what it captured (--record): replaying the recording must publish exactly the
# fed depths too.
#
# The ToF node is instance 0's capture node, fed known 'Y16 ' millimetre frames
# (/root/fed.y16, scripts/v4l2-vm/fed_frames.py) through vivid's output -> capture loop by
# capture_check; the RGB node is instance 1's capture node (YUYV webcam pattern).
#
# deard opens the ToF node through the link /dev/dear-tof (as a udev by-id link), which this
# script makes only once the feeder has set the loop up and streams: the feeder must change
# the capture node's input, timings and format, which vivid refuses (EBUSY) once deard streams
# it, and a freshly bound vivid starts on its webcam input. Whatever vivid delivers while no
# output buffer is looped in (its own test pattern: before the feeder, between the feeder's
# end and the unbind) lies beyond the module's 4 m range, so deard publishes it invalid and
# dear-v4l-check --allow-blank counts it without counting it as a fed frame.
node() { # node NAME: the /dev node whose sysfs name is NAME (vivid-000-vid-cap)
    for n in /sys/class/video4linux/*; do
        [ "$(cat "$n/name")" = "$1" ] && { echo "/dev/${n##*/}"; return 0; }
    done
    return 1
}
nodes() {
    tof=$(node vivid-000-vid-cap) && out=$(node vivid-000-vid-out) && rgb=$(node vivid-001-vid-cap)
}
wait_for() { # wait_for PATTERN FILE SECONDS
    i=0
    while ! grep -q "$1" "$2" 2>/dev/null; do
        i=$((i + 1)); [ $i -gt $(($3 * 10)) ] && return 1; sleep 0.1
    done
}
fail=0
step() { echo "== $*"; }
# start_feeder: feeds $out -> $tof in the background ($feeder) and, once it streams, links
# /dev/dear-tof to $tof; returns 1 (with its log) when it does not start.
start_feeder() {
    : > /tmp/feed-now.log
    capture_check feed "$out" "$tof" "Y16 " 640 480 /root/fed.y16 > /tmp/feed-now.log 2>&1 &
    feeder=$!
    ok=0
    wait_for feeding /tmp/feed-now.log 30 && ok=1
    cat /tmp/feed-now.log >> /tmp/feed.log
    if [ $ok = 0 ]; then
        echo "FAILED: the feeder did not start streaming $out:"; cat /tmp/feed-now.log
        return 1
    fi
    ln -sf "$tof" /dev/dear-tof
}
# The client: every frame exactly a fed one (depth beyond the module's range invalid), vivid's
# own pattern tolerated anywhere and counted.
v4l_check() { # v4l_check COUNT TIMEOUT_S
    dear-v4l-check --service dear/vm/frames --fed /root/fed.y16 --width 640 --height 480 \
        --max-range-m 4 --allow-blank --count "$1" --timeout-s "$2"
}
check() { # check DESCRIPTION COMMAND...: runs it, records a failure
    d=$1; shift
    if "$@"; then echo "ok: $d"; else echo "FAILED: $d"; fail=1; fi
}
nodes || { echo "deard-live: vivid nodes missing (n_devs=3 node_types=0x101,0x101,0x1?)"; exit 1; }
sed -i "s|/dev/video2|$rgb|" /root/deard.toml
echo "deard-live: ToF $tof (fed through $out, opened as /dev/dear-tof), RGB $rgb"

step "dear devices"
dear devices > /tmp/devices.txt 2>&1; rc=$?
cat /tmp/devices.txt
check "dear devices exits 0" [ $rc = 0 ]
check "dear devices lists the ToF node's 'Y16 ' as tof depth or amplitude" grep -q "format \"Y16 \".*\[tof depth or amplitude\]" /tmp/devices.txt
check "dear devices lists the Loop Video control" grep -q "loop_video" /tmp/devices.txt

step "feed $out -> $tof, start deard"
start_feeder || exit 1
RUST_LOG=info deard --config /root/deard.toml --stats-interval 2 --record /tmp/recording \
    > /tmp/deard.log 2>&1 &
daemon=$!
if ! wait_for serving /tmp/deard.log 120; then
    echo "FAILED: deard did not start serving"; cat /tmp/deard.log; exit 1
fi
grep -E "starting|depth beyond" /tmp/deard.log

step "a client receives the fed depth"
check "6 frames, each exactly one of the fed frames" v4l_check 6 180

step "the nodes vanish: vivid unbound"
kill $feeder 2>/dev/null; wait $feeder 2>/dev/null
rm -f /dev/dear-tof
dev=$(ls /sys/bus/platform/drivers/vivid/ | grep vivid | head -n1)
echo "$dev" > /sys/bus/platform/drivers/vivid/unbind
check "deard reports the lost node" wait_for "capture node lost" /tmp/deard.log 30
sleep 2
check "deard keeps running without its nodes" kill -0 $daemon

step "the nodes come back: vivid bound again"
echo "$dev" > /sys/bus/platform/drivers/vivid/bind
sleep 1
nodes || { echo "FAILED: vivid nodes did not come back"; fail=1; }
start_feeder || fail=1
check "deard reopens both nodes" wait_for "capture node is back" /tmp/deard.log 60
check "the client receives the fed depth again" v4l_check 4 180

step "stop"
kill -TERM $daemon
wait $daemon; rc=$?
check "deard exits 0 on SIGTERM" [ $rc = 0 ]
kill $feeder 2>/dev/null; wait $feeder 2>/dev/null
check "the recording is finished" grep -q "recording finished" /tmp/deard.log

step "replay the recording"
RUST_LOG=info deard --config /root/deard.toml --replay /tmp/recording --loop \
    > /tmp/replay.log 2>&1 &
replayer=$!
if wait_for serving /tmp/replay.log 60; then
    check "the replayed recording publishes the fed depth" v4l_check 4 120
else
    echo "FAILED: deard did not replay the recording"; cat /tmp/replay.log; fail=1
fi
kill -TERM $replayer; wait $replayer

step "three nodes: depth, amplitude (instance 2's GREY webcam) and RGB"
amp=$(node vivid-002-vid-cap) || { echo "FAILED: no third vivid instance"; fail=1; }
if [ -n "$amp" ]; then
    cp /root/deard.toml /root/deard-amp.toml
    printf '\n[capture.v4l.amplitude]\ndevice = "%s"\nformat = "GREY"\nwidth = 640\nheight = 480\nfps = 25\n' \
        "$amp" >> /root/deard-amp.toml
    start_feeder || fail=1
    RUST_LOG=info deard --config /root/deard-amp.toml > /tmp/amp.log 2>&1 &
    daemon=$!
    if wait_for serving /tmp/amp.log 60; then
        grep starting /tmp/amp.log
        # vivid's instances run on their own clocks: only depth frames with an amplitude frame
        # within a quarter period pair (about half of them here; a module's two images share
        # one exposure's timestamp).
        check "with an amplitude node, the client receives the fed depth" v4l_check 4 180
    else
        echo "FAILED: deard with an amplitude node did not start"; cat /tmp/amp.log; fail=1
    fi
    kill -TERM $daemon; wait $daemon
    kill $feeder 2>/dev/null
fi
echo "---- deard log (last 40 lines)"
tail -n 40 /tmp/deard.log
if [ $fail != 0 ]; then echo "---- feeder log"; cat /tmp/feed.log; fi
echo "deard-live: $([ $fail = 0 ] && echo PASSED || echo FAILED)"
exit $fail
