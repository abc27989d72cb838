#!/usr/bin/env python3
# SPDX-License-Identifier: BSD-3-Clause
"""A haptic device's driver program for spheretouch's UDP bridge, with the device emulated.

A real driver has the same loop around a vendor SDK (OpenHaptics hdScheduleAsynchronous, Force
Dimension dhdGetPosition/dhdSetForce, CHAI3D cGenericHapticDevice, libnifalcon): every tick, read
the tool tip and orientation, send them as a pose datagram, and apply the newest force datagram
that came back. Here the "device" follows a straight path back and forth and ignores the force;
the program measures what a driver would see: poses sent, forces received (every servo tick),
sequence gaps, and the pose-to-force time (from sending a pose to receiving the first force that
used it, on this program's clock, echoed by the servo).

Wire format (version 1, little-endian; src/spheretouch/rt/udp_device.hpp and docs/user-guide/devices.md):
  pose  (80 bytes): "STHP" u16 version u16 buttons u64 seq i64 device_ns f64 x y z f64 qw qx qy qz
  force (64 bytes): "STHF" u16 version u16 flags u64 seq u64 pose_seq i64 pose_device_ns
                    f64 fx fy fz i64 servo_ns

  spheretouch run configs/udp_small.toml &       # [device] kind = "udp", bind = "127.0.0.1:7600"
  examples/udp_device_emulator.py --seconds 3 --from 0,0,56 --to-point 0,0,48
"""
import argparse
import json
import math
import select
import socket
import struct
import sys
import time

POSE = struct.Struct("<4sHHQq3d4d")
FORCE = struct.Struct("<4sHHQQq3dq")
assert POSE.size == 80 and FORCE.size == 64


def vec(text):
    parts = [float(x) for x in text.split(",")]
    if len(parts) != 3 or not all(math.isfinite(x) for x in parts):
        raise argparse.ArgumentTypeError(f"'{text}': expected x,y,z (three finite numbers)")
    return parts


def endpoint(text):
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        raise argparse.ArgumentTypeError(f"'{text}': expected HOST:PORT")
    return host.strip("[]"), int(port)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--to", type=endpoint, default=("127.0.0.1", 7600), help="the bridge's HOST:PORT (default 127.0.0.1:7600)")
    ap.add_argument("--rate", type=float, default=1000.0, help="poses per second (default 1000)")
    ap.add_argument("--seconds", type=float, default=3.0, help="how long to drive (default 3)")
    ap.add_argument("--from", dest="start", type=vec, default=[0.0, 0.0, 60.0], help="tip path start x,y,z, device mm")
    ap.add_argument("--to-point", dest="end", type=vec, default=[0.0, 0.0, 40.0], help="tip path end x,y,z, device mm")
    ap.add_argument("--period", type=float, default=2.0, help="seconds for one sweep start -> end -> start (default 2)")
    ap.add_argument("--wait", type=float, default=10.0, help="seconds to wait for the bridge's first force (default 10)")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    a = ap.parse_args()
    if not (0 < a.rate <= 10000) or not (0 < a.seconds <= 86400) or not (a.period > 0):
        ap.error("--rate must be in (0, 10000], --seconds in (0, 86400], --period > 0")

    family = socket.AF_INET6 if ":" in a.to[0] else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_DGRAM)
    sock.connect(a.to)  # only the bridge's datagrams are received
    sock.setblocking(False)

    sent = {}  # pose seq -> send time, ns
    lat_us = []
    up_us = []    # pose sent -> the servo's tick that used it (one machine: both clocks are CLOCK_MONOTONIC)
    down_us = []  # the servo's send -> this program's receive
    forces = 0
    force_gaps = 0
    last_force_seq = 0
    echoed = set()
    max_force = 0.0
    fading = 0
    late = 0
    refused = 0

    def receive(until_ns):
        nonlocal forces, force_gaps, last_force_seq, max_force, fading, refused
        while True:
            now = time.monotonic_ns()
            timeout = max(0.0, (until_ns - now) / 1e9)
            r, _, _ = select.select([sock], [], [], timeout)
            if not r:
                return
            while True:
                try:
                    data = sock.recv(256)
                except BlockingIOError:
                    break
                except ConnectionRefusedError:  # the bridge is not up yet (ICMP port unreachable)
                    refused += 1
                    break
                t = time.monotonic_ns()
                if len(data) != FORCE.size:
                    continue
                magic, version, flags, seq, pose_seq, pose_ns, fx, fy, fz, servo_ns = FORCE.unpack(data)
                if magic != b"STHF" or version != 1:
                    continue
                forces += 1
                if last_force_seq and seq > last_force_seq + 1:
                    force_gaps += seq - last_force_seq - 1
                last_force_seq = max(last_force_seq, seq)
                if flags & 1:
                    fading += 1
                max_force = max(max_force, math.sqrt(fx * fx + fy * fy + fz * fz))
                if pose_seq not in echoed and pose_seq in sent and sent[pose_seq] == pose_ns:
                    echoed.add(pose_seq)
                    lat_us.append((t - pose_ns) / 1000.0)
                    up_us.append((servo_ns - pose_ns) / 1000.0)
                    down_us.append((t - servo_ns) / 1000.0)

    period_ns = int(1e9 / a.rate)
    seq = 0

    def send_pose(t_ns, t0):
        nonlocal seq
        seq += 1
        s = ((t_ns - t0) / 1e9) % a.period / a.period
        w = 2 * s if s < 0.5 else 2 - 2 * s  # 0 -> 1 -> 0
        tip = [p + w * (q - p) for p, q in zip(a.start, a.end)]
        sent[seq] = t_ns
        try:
            sock.send(POSE.pack(b"STHP", 1, 0, seq, t_ns, *tip, 1.0, 0.0, 0.0, 0.0))
        except ConnectionRefusedError:
            pass

    # Wait for the bridge: a pose every 10 ms until the first force comes back.
    t0 = time.monotonic_ns()
    while forces == 0:
        if time.monotonic_ns() - t0 > a.wait * 1e9:
            print(f"udp_device_emulator: no force from {a.to[0]}:{a.to[1]} within {a.wait} s", file=sys.stderr)
            return 1
        send_pose(time.monotonic_ns(), t0)
        receive(time.monotonic_ns() + 10_000_000)
    warmup = (seq, forces)
    sent.clear()
    echoed.clear()
    lat_us.clear()
    up_us.clear()
    down_us.clear()
    forces = force_gaps = fading = 0
    max_force = 0.0

    # The driver's loop at `rate`, absolute deadlines.
    t0 = time.monotonic_ns()
    first_seq = seq + 1
    deadline = t0
    end = t0 + int(a.seconds * 1e9)
    while deadline < end:
        now = time.monotonic_ns()
        if now - deadline > period_ns:
            late += 1
        send_pose(now, t0)
        deadline += period_ns
        receive(deadline)
    receive(time.monotonic_ns() + 50_000_000)  # forces still on their way
    elapsed = (time.monotonic_ns() - t0) / 1e9

    lat_us.sort()
    up_us.sort()
    down_us.sort()

    def q(p, v=lat_us):
        return v[min(len(v) - 1, int(p * len(v)))] if v else float("nan")

    out = {
        "poses_sent": seq - first_seq + 1,
        "first_seq": first_seq,
        "last_seq": seq,
        "warmup_poses": warmup[0],
        "forces_received": forces,
        "forces_per_s": forces / elapsed,
        "force_seq_gaps": force_gaps,
        "forces_fading": fading,
        "poses_echoed": len(lat_us),
        "pose_to_force_us_p50": q(0.5),
        "pose_to_force_us_p99": q(0.99),
        "pose_to_force_us_max": lat_us[-1] if lat_us else float("nan"),
        "pose_to_servo_us_p50": q(0.5, up_us),
        "pose_to_servo_us_p99": q(0.99, up_us),
        "servo_to_driver_us_p50": q(0.5, down_us),
        "servo_to_driver_us_p99": q(0.99, down_us),
        "max_force_N": max_force,
        "late_ticks": late,
        "seconds": elapsed,
    }
    if a.json:
        print(json.dumps(out))
    else:
        print(f"poses sent {out['poses_sent']} at {a.rate:.0f} Hz ({late} late), forces received {forces} "
              f"({out['forces_per_s']:.1f}/s, {force_gaps} seq gaps, {fading} fading), max |F| {max_force:.3f} N")
        print(f"pose-to-force over {len(lat_us)} poses: p50 {q(0.5):.0f} us, p99 {q(0.99):.0f} us, "
              f"max {out['pose_to_force_us_max']:.0f} us")
        print(f"  of which pose -> the servo tick that used it: p50 {q(0.5, up_us):.0f} us, p99 {q(0.99, up_us):.0f} us; "
              f"servo -> driver: p50 {q(0.5, down_us):.0f} us, p99 {q(0.99, down_us):.0f} us (same machine only)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
