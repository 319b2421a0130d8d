#!/bin/busybox sh
# PID 1 of the test VM (copied into the initramfs as /init by build_initramfs.py).
# Mounts the host's root read-only over virtio-9p with a tmpfs overlay on top, brings up
# vcan0, runs /out/cmd.sh (written by run-in-vm.sh) chrooted into that root, and leaves
# the command's exit status and the kernel log in the writable share /out.
/bin/busybox mkdir -p /proc /sys /dev
/bin/busybox mount -t devtmpfs dev /dev
exec </dev/console >/dev/console 2>&1
/bin/busybox --install -s /bin
export PATH=/bin
mount -t proc proc /proc
mount -t sysfs sys /sys

fail() { echo "vm-init: $*"; dmesg | tail -40; sync; poweroff -f; }

while read -r mod; do
  insmod "/lib/modules/$mod" || fail "insmod $mod failed"
done </modules.list

mkdir -p /host /out /ovl /newroot
# cache=loose: the host root is read-only for the guest and does not change under a test.
mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000,cache=loose,ro hostroot /host \
  || fail "cannot mount the host root (9p tag hostroot)"
mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 out /out \
  || fail "cannot mount the result share (9p tag out)"
mount -t tmpfs -o size=1200m tmpfs /ovl
mkdir -p /ovl/upper /ovl/work
mount -t overlay overlay -o lowerdir=/host,upperdir=/ovl/upper,workdir=/ovl/work /newroot \
  || fail "cannot mount the overlay"
# The guest's own kernel file systems replace the host's (seen through 9p).
mount -t proc proc /newroot/proc
mount -t sysfs sys /newroot/sys
mount -t devtmpfs dev /newroot/dev
mkdir -p /newroot/dev/pts /newroot/dev/shm
mount -t devpts devpts /newroot/dev/pts
mount -t tmpfs tmpfs /newroot/dev/shm
mount -t tmpfs tmpfs /newroot/run
mkdir -p /newroot/run/vm-out
mount --bind /out /newroot/run/vm-out

ip link set lo up
ip link add dev vcan0 type vcan && ip link set vcan0 up || fail "cannot create vcan0"

echo "vm-init: up in $(cut -d' ' -f1 /proc/uptime) s; running the command"
chroot /newroot /bin/bash /run/vm-out/cmd.sh
echo $? >/out/rc.tmp
mv /out/rc.tmp /out/rc
dmesg >/out/dmesg.txt
sync
umount /newroot/run/vm-out
umount /out
poweroff -f
