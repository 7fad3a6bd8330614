#!/bin/sh
# Guest script of `scripts/test-v4l2-vm.sh --self-test` (busybox sh; capture_check is
# scripts/v4l2-vm/capture_check.c). Fails when vivid has no readable capture node, when its
# frames are not flagged monotonic, or when the output -> capture loop does not give back the
# written Y16 frame byte for byte. Other formats' loops are reported, not required.
node() { # node NAME-SUFFIX: the /dev node whose sysfs name ends in it (vivid-000-vid-cap)
    for n in /sys/class/video4linux/*; do
        case "$(cat "$n/name")" in *"$1") echo "/dev/${n##*/}"; return 0 ;; esac
    done
    return 1
}
cap=$(node vid-cap) || { echo "self-test: no vivid video capture node"; exit 1; }
out=$(node vid-out) || out=
echo "self-test: capture node $cap, output node ${out:-none}"
echo "== capture_check list"
capture_check list
fail=0
for f in "Y16 " YUYV; do
    echo "== capture $cap '$f' 640x480"
    capture_check capture "$cap" "$f" 640 480 5 || fail=1
done
if [ -n "$out" ]; then
    echo "== loop $out -> $cap 'Y16 ' 640x480, one known frame"
    capture_check loop "$out" "$cap" "Y16 " 640 480 5 || fail=1
    # Three distinct frames written round-robin: each captured frame must be one of them, whole
    # (no frame torn between two output buffers).
    head -c $((640 * 480 * 2 * 3)) /dev/urandom > /tmp/frames.y16
    echo "== loop $out -> $cap 'Y16 ' 640x480, three frames from a file"
    capture_check loop "$out" "$cap" "Y16 " 640 480 8 /tmp/frames.y16 || fail=1
    # What the daemon's test does: one process feeds the output node, another captures.
    echo "== feed $out from a file, capture $cap in another process"
    capture_check feed "$out" "$cap" "Y16 " 640 480 /tmp/frames.y16 6 &
    feeder=$!
    sleep 2
    capture_check capture "$cap" "Y16 " 640 480 8 /tmp/frames.y16 || fail=1
    wait $feeder || fail=1
    exact="" inexact=""
    for f in GREY "Y12 " YUYV NV12 RGB3 BA81; do
        echo "== loop $out -> $cap '$f' 640x480 (informational)"
        if capture_check loop "$out" "$cap" "$f" 640 480 2; then
            exact="$exact '$f'"
        else
            inexact="$inexact '$f'"
        fi
    done
    echo "self-test: loop exact for 'Y16 '$exact; not exact for:${inexact:- none}"
else
    echo "self-test: no output node (vivid node_types without 0x100): loop not tested"
    fail=1
fi
echo "self-test: $([ $fail = 0 ] && echo PASSED || echo FAILED)"
exit $fail
