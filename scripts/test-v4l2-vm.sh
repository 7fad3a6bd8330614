#!/usr/bin/env bash
# Boots a real Linux kernel with the vivid V4L2 test driver under qemu (TCG: no KVM needed) and
# runs host binaries inside it (issue 14: the kernel's own V4L2, in a virtual machine).
#
#   scripts/test-v4l2-vm.sh --self-test
#   scripts/test-v4l2-vm.sh [--bin PATH]... [--file SRC:DEST]... [--vivid-params 'k=v ...']
#                           [--timeout S] --run GUEST_SCRIPT
#   scripts/test-v4l2-vm.sh --prepare        only install the packages and cache the kernel
#
#   --bin PATH        a host binary, copied to the guest's /bin with every library ldd lists
#                     for it (and the dynamic loader); repeatable. Its debug information is
#                     stripped (strip --strip-debug; symbols stay) unless --no-strip
#   --file SRC:DEST   a host file or directory copied to DEST in the guest; repeatable
#   --run SCRIPT      the guest script (busybox sh) that /init runs once vivid is loaded; this
#                     script exits with its exit status
#   --vivid-params P  vivid's module parameters (default: none, vivid's defaults, below)
#   --timeout S       wall-clock limit of the VM in seconds (default 600)
#   --self-test       boots, lists vivid's nodes and formats, streams frames from its capture
#                     node and checks the output -> capture loop byte for byte
#                     (scripts/v4l2-vm/self-test.sh with scripts/v4l2-vm/capture_check.c)
#   --deard           the daemon end to end (scripts/v4l2-vm/deard-live.sh): three vivid
#                     instances; known 'Y16 ' depth frames (millimetres) are fed into the first
#                     one's output and looped into its capture node (the ToF node), the second's
#                     capture node is the RGB node (YUYV); deard (target/release, built first:
#                     cargo build --release -p deard -p dear-cli -p dear-tools) captures
#                     both with refine = "none" and a zero calibration, and dear-v4l-check must
#                     receive exactly the fed depths, with the fed block beyond the module's
#                     max_range_m (4 m) published invalid; then vivid is unbound and bound
#                     again (the nodes vanish and return) and frames must flow again. deard
#                     opens the ToF node through a link the guest makes once the feeder
#                     streams (the feeder cannot set the loop up on a node deard streams);
#                     vivid's own pattern, whenever it comes, is beyond the 4 m range, published
#                     invalid, and counted by the checker, not taken for a fed frame
#
# Environment: DEAR_VM_CACHE (default ~/.cache/dear/v4l2-vm: the kernel .deb and the prepared
# kernel + decompressed modules, per kernel version), DEAR_VM_KERNEL (a Debian kernel ABI, e.g.
# 6.1.0-56-amd64; default that one, else the newest linux-image-6.1.0-*-amd64 apt offers),
# DEAR_VM_MEM (guest MiB; default 512, or more when the initramfs is large: the kernel holds
# the image and its unpacked copy in RAM, and the root tmpfs gets half of it).
#
# Installs when missing (apt-get, as root or with sudo): qemu-system-x86 (without recommends),
# busybox-static, kmod, cpio, xz-utils; and gcc for --self-test (build-essential).
#
# The guest: a busybox initramfs; /init (scripts/v4l2-vm/init) mounts proc, sysfs, devtmpfs,
# tmpfs on /dev/shm, /tmp and /run (iceoryx2 needs /dev/shm and /tmp writable), insmods the
# modules `modprobe --show-depends vivid` lists (decompressed on the host: busybox insmod reads
# no .ko.xz) in that order, prints `ls -l /dev/video*` and the nodes' names, runs the --run
# script as `sh /etc/dear-vm/run.sh` in /root, prints DEAR-VM-EXIT=<status> and powers off.
# The console (ttyS0) is printed here as it comes and kept in the log named at the end.
#
# Findings (Debian 6.1.0-56-amd64, qemu 7.2 TCG, -smp 1 -m 512, on the 2-core dev machine;
# the self-test's console shows all of it):
# - Modules, in load order: rc-core cec mc videodev videobuf2-common videobuf2-v4l2
#   videobuf2-memops videobuf2-vmalloc videobuf2-dma-contig v4l2-dv-timings v4l2-tpg vivid.
# - vivid with no parameters (node_types 0xe1d3d) creates:
#   /dev/video0 vivid-000-vid-cap    video capture; inputs 0 'Webcam 0' (the default), 1 'TV 0',
#                                    2 'S-Video 0', 3 'HDMI 0'
#   /dev/video1 vivid-000-vid-out    video output; outputs 0 'S-Video 0' (default), 1 'HDMI 0'
#   /dev/video2 vivid-000-meta-cap, /dev/video3 vivid-000-meta-out, /dev/vbi0 (capture),
#   /dev/vbi1 (output), /dev/radio0 (rx), /dev/radio1 (tx), /dev/swradio0, /dev/v4l-touch0.
#   --vivid-params 'n_devs=1 node_types=0x101': only /dev/video0 (capture) and /dev/video1
#   (output). Nodes are root-only (crw-------); the guest runs everything as root.
# - Formats: capture and output offer the same 83 single-planar formats: packed/planar YUV
#   (YUYV UYVY YVYU VYUY 422P YU12 YV12 NV12 NV21 NV16 NV61 NV24 NV42 ...), grey GREY 'Y10 '
#   'Y12 ' 'Y16 ' and big-endian 'Y16 ', RGB/BGR 8 to 32 bit (RGB3 BGR3 RGB4 XR24 AR24 ...),
#   Bayer 8/10/12/16 bit (BA81 GBRG GRBG RGGB ... BYR2 GB16 GR16 RG16), HSV3 HSV4. No 'Z16 ',
#   no 'Y12P', no MJPG. Sizes on the Webcam input: discrete 320x180, 640x360, 640x480,
#   1280x720, 1920x1080, 3840x2160, intervals 1/1 .. 1/60 (640x480: down to 1/25); after
#   S_FMT 640x480 the interval is 1/5 s (set VIDIOC_S_PARM for more). On HDMI the size and
#   rate follow the DV timings (640x480p59.94: 4200/251750 s); the output node has no
#   ENUM_FRAMESIZES.
# - Frames: V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC, end-of-frame timestamps, bytesused ==
#   sizeimage ('Y16 ' 640x480: bytesperline 1280, 614400 bytes). The first two frames after
#   STREAMON may both carry sequence 0, and sequences skip when no buffer is queued.
# - Loop (output -> capture; vivid.rst "Video, VBI and RDS Looping"): on the output node select
#   the 'HDMI 0' output and on the capture node the 'HDMI 0' input (or S-Video on both with
#   the same 50/60 Hz standard), give both the same DV timings (the CEA 640x480p59.94 preset
#   from VIDIOC_ENUM_DV_TIMINGS), the same format, size and field (NONE) on both, set the
#   capture node's "OSD Text Mode" control to 2 (None: otherwise vivid draws its counters at
#   16,16 over the looped picture, about 10 % of the bytes) and its "Loop Video" control to 1
#   (vivid-private IDs, 0x00f0f001 and 0x00f0f025 on 6.1, renumbered between kernels: look
#   them up by name), stream the output node. The capture node then returns byte-exact
#   copies of output buffers: verified for 'Y16 ', GREY, 'Y12 ', YUYV, NV12, RGB3, BA81 at
#   640x480 (random bytes, so 'Y12 ' values above 4095 pass through too). Capture (59.94 Hz)
#   and output run independently: a captured frame is a whole output frame (never torn), but
#   frames repeat or are skipped, so an end-to-end test must identify each received frame
#   (e.g. among the set it fed), not expect them in order. Input, timings, format and the
#   controls stay set after close: `capture_check feed` prepares the capture node, closes it
#   and keeps feeding, and another process (deard) captures; the self-test does exactly that.
# - Timings: guest /init starts 2.0-2.6 s after boot, vivid is loaded 0.35 s later, the first
#   frame comes within 10 ms of STREAMON. Host wall time: a trivial --run script 7.5-9 s
#   (qemu, firmware, kernel, poweroff), --self-test 15-17 s warm; a fresh cache adds the 70.6 MB
#   download and 9-12 s of preparation (30 s in all); a machine without the packages adds the
#   apt-get install (about 10 s here).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
vm_dir=$here/v4l2-vm

die() { echo "test-v4l2-vm: $*" >&2; exit 1; }
as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
SCRIPT_NAME=test-v4l2-vm
# shellcheck source=scripts/lib.sh
. "$here/lib.sh"

bins=() files=() run_script="" vivid_params="" vm_timeout=600 self_test=false prepare_only=false
deard=false
strip=true
while [ $# -gt 0 ]; do
    case "$1" in
        --bin) [ $# -ge 2 ] || die "--bin needs a path"; bins+=("$2"); shift 2 ;;
        --file) [ $# -ge 2 ] || die "--file needs SRC:DEST"; files+=("$2"); shift 2 ;;
        --run) [ $# -ge 2 ] || die "--run needs a script"; run_script=$2; shift 2 ;;
        --vivid-params) [ $# -ge 2 ] || die "--vivid-params needs a value"; vivid_params=$2; shift 2 ;;
        --timeout) [ $# -ge 2 ] || die "--timeout needs seconds"; vm_timeout=$2; shift 2 ;;
        --self-test) self_test=true; shift ;;
        --deard) deard=true; shift ;;
        --no-strip) strip=false; shift ;;
        --prepare) prepare_only=true; shift ;;
        -h | --help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;;
        *) die "unknown argument '$1' (see --help)" ;;
    esac
done
if ! $self_test && ! $deard && ! $prepare_only; then
    [ -n "$run_script" ] || die "nothing to run: give --run SCRIPT, --self-test or --deard (see --help)"
fi
# --deard: three vivid instances: two with a capture and an output node, one capture only.
if $deard && [ -z "$vivid_params" ]; then vivid_params='n_devs=3 node_types=0x101,0x101,0x1'; fi
[ -z "$run_script" ] || [ -f "$run_script" ] || die "--run: no file $run_script"
for b in "${bins[@]+"${bins[@]}"}"; do [ -f "$b" ] || die "--bin: no file $b"; done
for f in "${files[@]+"${files[@]}"}"; do
    case "$f" in *:/*) ;; *) die "--file wants SRC:/ABSOLUTE/DEST, got '$f'" ;; esac
    [ -e "${f%%:*}" ] || die "--file: no file or directory ${f%%:*}"
done
[[ "$vm_timeout" =~ ^[0-9]+$ ]] || die "--timeout wants whole seconds, got '$vm_timeout'"

t_start=$(now)

# ---- host packages
static_busybox() { # prints a statically linked busybox, if there is one
    local b
    for b in /bin/busybox /usr/bin/busybox; do
        if [ -x "$b" ] && ! ldd "$b" >/dev/null 2>&1; then echo "$b"; return 0; fi
    done
    return 1
}
need=()
command -v qemu-system-x86_64 >/dev/null || need+=(qemu-system-x86)
static_busybox >/dev/null || need+=(busybox-static)
command -v depmod >/dev/null && command -v modprobe >/dev/null || need+=(kmod)
command -v cpio >/dev/null || need+=(cpio)
command -v xz >/dev/null || need+=(xz-utils)
if { $self_test || $deard; } && ! command -v gcc >/dev/null; then need+=(build-essential); fi
if [ ${#need[@]} -gt 0 ]; then
    command -v apt-get >/dev/null || die "missing ${need[*]} and no apt-get to install them"
    echo "test-v4l2-vm: installing ${need[*]}"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${need[@]}" >/dev/null
fi
busybox=$(static_busybox) || die "no statically linked busybox (Debian package busybox-static)"
command -v qemu-system-x86_64 >/dev/null || die "qemu-system-x86_64 missing (Debian qemu-system-x86)"
# Debian puts depmod/modprobe in /usr/sbin, which a user's PATH may lack.
export PATH=$PATH:/usr/sbin:/sbin
command -v depmod >/dev/null || die "depmod missing (Debian kmod)"

# ---- the kernel and vivid's modules, cached per version
cache=${DEAR_VM_CACHE:-$HOME/.cache/dear/v4l2-vm}
mkdir -p "$cache/debs"
apt_has() { apt-cache show "linux-image-$1" >/dev/null 2>&1; }
kver=${DEAR_VM_KERNEL:-}
if [ -z "$kver" ]; then
    kver=6.1.0-56-amd64 # verified in issue 14
    if [ ! -f "$cache/$kver/.ready" ] && ! apt_has "$kver"; then
        as_root apt-get update -qq || true
        if ! apt_has "$kver"; then
            newest=$(apt-cache search --names-only '^linux-image-6\.1\.0-[0-9]+-amd64$' \
                | awk '{ print $1 }' | sed 's/^linux-image-//' | sort -t- -k2,2n | tail -n1)
            [ -n "$newest" ] || die "apt offers no linux-image-6.1.0-*-amd64 (Debian 12 sources?)"
            echo "test-v4l2-vm: linux-image-$kver is not offered here; using linux-image-$newest"
            kver=$newest
        fi
    fi
fi
kdir=$cache/$kver
if [ ! -f "$kdir/.ready" ]; then
    t_prep=$(now)
    deb=$(find "$cache/debs" -maxdepth 1 -name "linux-image-${kver}_*.deb" | head -n1)
    if [ -z "$deb" ]; then
        if ! apt_has "$kver"; then as_root apt-get update -qq || true; fi
        apt_has "$kver" || die "apt offers no linux-image-$kver (set DEAR_VM_KERNEL to one it has)"
        echo "test-v4l2-vm: downloading linux-image-$kver"
        # As root apt warns that it downloads unsandboxed: drop the W: lines; the check below
        # names a failed download.
        (cd "$cache/debs"; apt-get download -q "linux-image-$kver" 2>&1 | grep -v '^W: ') || true
        deb=$(find "$cache/debs" -maxdepth 1 -name "linux-image-${kver}_*.deb" | head -n1)
        [ -n "$deb" ] || die "apt-get download linux-image-$kver gave no .deb in $cache/debs"
    fi
    echo "test-v4l2-vm: preparing $kver from ${deb##*/}"
    rm -rf "$kdir" "$kdir.tmp"
    mkdir -p "$kdir.tmp/modules"
    x=$kdir.tmp/x
    nice dpkg -x "$deb" "$x"
    [ -f "$x/boot/vmlinuz-$kver" ] || die "${deb##*/} has no boot/vmlinuz-$kver"
    # depmod wants the modules under <root>/lib/modules (Debian 12 has them there, merged /usr
    # later: accept both).
    if [ ! -d "$x/lib/modules/$kver" ] && [ -d "$x/usr/lib/modules/$kver" ]; then
        mkdir -p "$x/lib/modules" && mv "$x/usr/lib/modules/$kver" "$x/lib/modules/"
    fi
    nice depmod -b "$x" "$kver"
    modprobe -d "$x" -S "$kver" --show-depends vivid | awk '$1 == "insmod" { print $2 }' \
        > "$kdir.tmp/paths"
    [ -s "$kdir.tmp/paths" ] || die "modprobe --show-depends vivid lists nothing for $kver"
    : > "$kdir.tmp/modules.order"
    while read -r p; do
        name=${p##*/}
        case "$name" in
            *.ko.xz) nice xz -dc "$p" > "$kdir.tmp/modules/${name%.xz}"; name=${name%.xz} ;;
            *.ko.zst) nice zstd -qdc "$p" > "$kdir.tmp/modules/${name%.zst}"; name=${name%.zst} ;;
            *.ko.gz) nice gzip -dc "$p" > "$kdir.tmp/modules/${name%.gz}"; name=${name%.gz} ;;
            *.ko) cp "$p" "$kdir.tmp/modules/$name" ;;
            *) die "unexpected module file $p" ;;
        esac
        echo "$name" >> "$kdir.tmp/modules.order"
    done < "$kdir.tmp/paths"
    cp "$x/boot/vmlinuz-$kver" "$kdir.tmp/vmlinuz"
    rm -rf "$x" "$kdir.tmp/paths"
    mv "$kdir.tmp" "$kdir"
    touch "$kdir/.ready"
    echo "test-v4l2-vm: kernel $kver ready in $(since "$t_prep") s" \
        "($(wc -l < "$kdir/modules.order") modules: $(tr '\n' ' ' < "$kdir/modules.order"))"
fi
if $prepare_only; then
    echo "test-v4l2-vm: $kdir ready ($(since "$t_start") s)"
    exit 0
fi

# ---- the initramfs
work=$(mktemp -d "${TMPDIR:-/tmp}/dear-vm.XXXXXX")
trap 'rm -rf "$work"' EXIT
root=$work/root
mkdir -p "$root"/{bin,sbin,usr/bin,usr/sbin,etc/dear-vm,lib/modules/dear-vm,proc,sys,dev,tmp,run,root}
cp "$busybox" "$root/bin/busybox"
for applet in $("$busybox" --list); do
    [ -e "$root/bin/$applet" ] || ln -s busybox "$root/bin/$applet"
done
cp "$kdir"/modules/*.ko "$root/lib/modules/dear-vm/"
cp "$kdir/modules.order" "$root/etc/dear-vm/modules"
printf '%s\n' "$vivid_params" > "$root/etc/dear-vm/vivid-params"
cp "$vm_dir/init" "$root/init"
chmod 755 "$root/init"
printf 'root:x:0:0:root:/root:/bin/sh\n' > "$root/etc/passwd"
printf 'root:x:0:\nvideo:x:44:\n' > "$root/etc/group"

add_libs() { # the libraries (and loader) ldd lists for $1, at their own paths
    local line lib
    # ldd fails on a static binary: no libraries then.
    { ldd "$1" 2>/dev/null || true; } | while read -r line; do
        case "$line" in
            *"=> /"*) lib=${line#*=> }; lib=${lib%% (*} ;;
            /*) lib=${line%% (*} ;;
            *) continue ;;
        esac
        if [ ! -e "$root$lib" ]; then
            mkdir -p "$root$(dirname "$lib")"
            cp -L "$lib" "$root$lib"
        fi
    done
}
if $self_test || $deard; then
    nice gcc -O2 -Wall -static -o "$work/capture_check" "$vm_dir/capture_check.c" \
        || die "gcc could not build scripts/v4l2-vm/capture_check.c (static: needs libc6-dev)"
    bins+=("$work/capture_check")
fi
if $self_test; then
    [ -n "$run_script" ] || run_script=$vm_dir/self-test.sh
fi
if $deard; then
    release=$(cd "$vm_dir/../.." && pwd)/target/release
    for b in deard dear dear-v4l-check; do
        [ -x "$release/$b" ] || die "--deard needs $release/$b: cargo build --release -p deard -p dear-cli -p dear-tools"
        bins+=("$release/$b")
    done
    python3 "$vm_dir/fed_frames.py" 640 480 4 > "$work/fed.y16"
    files+=("$work/fed.y16:/root/fed.y16" "$vm_dir/module.toml:/root/module.toml"
            "$vm_dir/deard.toml:/root/deard.toml")
    [ -n "$run_script" ] || run_script=$vm_dir/deard-live.sh
fi
for b in "${bins[@]+"${bins[@]}"}"; do
    cp -L "$b" "$root/bin/${b##*/}"
    chmod 755 "$root/bin/${b##*/}"
    # A debug build's DWARF (deard: 167 MB -> about 20) would not fit the guest's RAM.
    if $strip && command -v strip >/dev/null; then strip --strip-debug "$root/bin/${b##*/}"; fi
    add_libs "$b"
done
for f in "${files[@]+"${files[@]}"}"; do
    src=${f%%:*} dest=${f#*:}
    mkdir -p "$root$(dirname "$dest")"
    cp -a "$src" "$root$dest"
done
cp "$run_script" "$root/etc/dear-vm/run.sh"
(cd "$root" && find . -print0 | cpio --null -o -H newc --quiet) > "$work/initrd.cpio"
initrd_mib=$(du -m "$work/initrd.cpio" | cut -f1)
mem=${DEAR_VM_MEM:-$((initrd_mib * 3 + 256 > 512 ? initrd_mib * 3 + 256 : 512))}
echo "test-v4l2-vm: initramfs ${initrd_mib} MiB, guest RAM ${mem} MiB" \
    "(${#bins[@]} binaries, ${#files[@]} files), kernel $kver, vivid params '${vivid_params}'"

# ---- boot
log=${DEAR_VM_LOG:-$cache/last-console.log}
t_boot=$(now)
echo "test-v4l2-vm: booting (timeout ${vm_timeout} s)"
set +e
timeout --kill-after=10 "$vm_timeout" nice qemu-system-x86_64 -accel tcg -cpu max -smp 1 \
    -m "$mem" -nographic -nic none -no-reboot -kernel "$kdir/vmlinuz" \
    -initrd "$work/initrd.cpio" -append 'console=ttyS0 quiet panic=-1' < /dev/null \
    2>&1 | sed -u -e 's/\r$//' -e 's/\r/\n/g' -e 's/\x1b\[[0-9;?]*[A-Za-z]//g' -e 's/\x1bc//g' | tee "$log"
qemu_rc=${PIPESTATUS[0]}
set -e
boot_s=$(since "$t_boot")
status=$(sed -n 's/.*DEAR-VM-EXIT=\([0-9][0-9]*\)$/\1/p' "$log" | tail -n1)
echo "test-v4l2-vm: VM ran ${boot_s} s; total $(since "$t_start") s; console log $log"
if [ -z "$status" ]; then
    if [ "$qemu_rc" = 124 ] || [ "$qemu_rc" = 137 ]; then
        die "the VM timed out after ${vm_timeout} s without a DEAR-VM-EXIT line"
    elif grep -q 'Kernel panic' "$log"; then
        die "the guest kernel panicked (see the console above): no DEAR-VM-EXIT line"
    fi
    die "the VM stopped (qemu status $qemu_rc) without a DEAR-VM-EXIT line"
fi
echo "test-v4l2-vm: guest script exited $status"
exit "$status"
