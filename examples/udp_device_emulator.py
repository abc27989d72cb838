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

Wire format (version 2, little-endian; src/spheretouch/rt/udp_device.hpp and docs/user-guide/devices.md):
  pose  (120 bytes): "STHP" u16 version u16 buttons u64 session u64 seq i64 device_ns
                     f64 x y z f64 qw qx qy qz, tag[32] = HMAC-SHA256(key, bytes 0-87)
  force (128 bytes): "STHF" u16 version u16 flags u64 session u64 seq u64 pose_seq i64 pose_device_ns
                     f64 fx fy fz f64 tx ty tz i64 servo_ns, tag[32] = HMAC-SHA256(key, bytes 0-95)
  refusal (80 bytes): "STHR" u16 version u16 reason u64 session char[64] reason in words
Version 1 (--protocol 1: an 80-byte pose and a 64-byte force without session, torque and tag) is
taken only by a scene with [device] auth = "none"; a bridge that authenticates refuses it.

  spheretouch run configs/udp_small.toml --out run &   # prints "this run's key is in run/bridge.key"
  examples/udp_device_emulator.py --key run/bridge.key --seconds 3 --from 0,0,56 --to-point 0,0,48
"""
import argparse
import hashlib
import hmac
import json
import math
import os
import select
import socket
import struct
import sys
import time

POSE = struct.Struct("<4sHHQQq3d4d")    # version 2, before the tag
FORCE = struct.Struct("<4sHHQQQq3d3dq")  # version 2, before the tag
POSE1 = struct.Struct("<4sHHQq3d4d")     # version 1
FORCE1 = struct.Struct("<4sHHQQq3dq")    # version 1
REFUSAL = struct.Struct("<4sHHQ64s")
TAG = 32
assert POSE.size + TAG == 120 and FORCE.size + TAG == 128 and POSE1.size == 80 and FORCE1.size == 64
assert REFUSAL.size == 80
REASONS = {1: "version 1 refused: the bridge authenticates (use --protocol 2 with --key)",
           2: "the tag does not verify: wrong --key",
           3: "another session holds the device (it is taken after the other driver is silent)",
           4: "this session id was served before"}


def read_key(path):
    """The bridge key: 64 hexadecimal digits on the first line of a file only its owner can read."""
    try:
        st = os.stat(path)
        with open(path, encoding="ascii") as f:
            line = f.readline().strip()
    except (OSError, UnicodeDecodeError) as e:
        raise SystemExit(f"udp_device_emulator: {path}: cannot read the bridge key: {e}")
    if st.st_mode & 0o077:
        raise SystemExit(f"udp_device_emulator: {path}: the bridge key is readable by group or others (chmod 600 {path})")
    try:
        key = bytes.fromhex(line)
    except ValueError:
        key = b""
    if len(key) != 32:
        raise SystemExit(f"udp_device_emulator: {path}: expected 64 hexadecimal digits on the first line")
    return key


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
    ap.add_argument("--key", help="the bridge key file (the scene's [device] key_file, or the run's RUN_DIR/bridge.key)")
    ap.add_argument("--protocol", type=int, choices=(1, 2), default=2,
                    help="wire version: 2 (default; authenticated with --key, or unauthenticated without it for a "
                         "scene with auth = \"none\"), or 1 (legacy, only for auth = \"none\")")
    ap.add_argument("--trace", metavar="CSV", help="write every force received: t_s, fx, fy, fz (N), tx, ty, tz (N·m), "
                    "flags (plot: gnuplot -e \"set datafile separator ','; plot 'F' using 1:2 w l, '' using 1:5 w l\")")
    ap.add_argument("--print-every", type=int, default=0, metavar="N",
                    help="print every Nth force and torque as it arrives (0: none)")
    a = ap.parse_args()
    if not (0 < a.rate <= 10000) or not (0 < a.seconds <= 86400) or not (a.period > 0):
        ap.error("--rate must be in (0, 10000], --seconds in (0, 86400], --period > 0")
    if a.protocol == 1 and a.key:
        ap.error("--protocol 1 has no authentication: drop --key (or speak version 2)")
    key = read_key(a.key) if a.key else None
    session = int.from_bytes(os.urandom(8), "little") or 1  # random: a restarted driver is a new session
    trace = open(a.trace, "w", encoding="ascii") if a.trace else None
    if trace:
        trace.write("t_s,fx_N,fy_N,fz_N,tx_Nm,ty_Nm,tz_Nm,flags\n")

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
    max_torque = 0.0
    fading = 0
    limited = 0
    late = 0
    refused = 0
    refusals = {}  # reason -> count
    forged = 0     # force datagrams whose tag did not verify (dropped)
    t_start = time.monotonic_ns()

    def decode(data):
        """(flags, seq, pose_seq, pose_ns, force, torque, servo_ns), or None for a datagram that is not a force for us."""
        nonlocal forged
        if len(data) == REFUSAL.size and data[:4] == b"STHR":
            _, _, reason, _, text = REFUSAL.unpack(data)
            if reason not in refusals:
                words = text.split(b"\0", 1)[0].decode("ascii", "replace")
                print(f"udp_device_emulator: the bridge refused: {words} "
                      f"({REASONS.get(reason, 'reason ' + str(reason))})", file=sys.stderr)
            refusals[reason] = refusals.get(reason, 0) + 1
            return None
        if a.protocol == 1:
            if len(data) != FORCE1.size:
                return None
            magic, version, flags, seq, pose_seq, pose_ns, fx, fy, fz, servo_ns = FORCE1.unpack(data)
            if magic != b"STHF" or version != 1:
                return None
            return flags, seq, pose_seq, pose_ns, (fx, fy, fz), (0.0, 0.0, 0.0), servo_ns
        if len(data) != FORCE.size + TAG:
            return None
        if key is not None and not hmac.compare_digest(hmac.new(key, data[:FORCE.size], hashlib.sha256).digest(),
                                                       data[FORCE.size:]):
            forged += 1
            return None
        (magic, version, flags, sess, seq, pose_seq, pose_ns, fx, fy, fz, tx, ty, tz,
         servo_ns) = FORCE.unpack(data[:FORCE.size])
        if magic != b"STHF" or version != 2 or sess != session:
            return None
        return flags, seq, pose_seq, pose_ns, (fx, fy, fz), (tx, ty, tz), servo_ns

    def receive(until_ns):
        nonlocal forces, force_gaps, last_force_seq, max_force, max_torque, fading, limited, refused
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
                d = decode(data)
                if d is None:
                    continue
                flags, seq, pose_seq, pose_ns, force, torque, servo_ns = d
                forces += 1
                if last_force_seq and seq > last_force_seq + 1:
                    force_gaps += seq - last_force_seq - 1
                last_force_seq = max(last_force_seq, seq)
                if flags & 1:
                    fading += 1
                if flags & 4:
                    limited += 1
                max_force = max(max_force, math.sqrt(sum(v * v for v in force)))
                max_torque = max(max_torque, math.sqrt(sum(v * v for v in torque)))
                if trace:
                    trace.write(f"{(t - t_start) / 1e9:.6f},{force[0]:.6g},{force[1]:.6g},{force[2]:.6g},"
                                f"{torque[0]:.6g},{torque[1]:.6g},{torque[2]:.6g},{flags}\n")
                if a.print_every and forces % a.print_every == 0:
                    print(f"force {forces}: F = ({force[0]:+.4f}, {force[1]:+.4f}, {force[2]:+.4f}) N, "
                          f"tau = ({torque[0]:+.5f}, {torque[1]:+.5f}, {torque[2]:+.5f}) N·m", file=sys.stderr)
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
        if a.protocol == 1:
            data = POSE1.pack(b"STHP", 1, 0, seq, t_ns, *tip, 1.0, 0.0, 0.0, 0.0)
        else:
            body = POSE.pack(b"STHP", 2, 0, session, seq, t_ns, *tip, 1.0, 0.0, 0.0, 0.0)
            data = body + (hmac.new(key, body, hashlib.sha256).digest() if key is not None else bytes(TAG))
        try:
            sock.send(data)
        except ConnectionRefusedError:
            pass

    # Wait for the bridge: a pose every 10 ms until the first force comes back.
    t0 = time.monotonic_ns()
    while forces == 0:
        if time.monotonic_ns() - t0 > a.wait * 1e9:
            why = "; refused: " + ", ".join(REASONS.get(r, str(r)) for r in refusals) if refusals else ""
            print(f"udp_device_emulator: no force from {a.to[0]}:{a.to[1]} within {a.wait} s{why}", file=sys.stderr)
            if a.json:
                print(json.dumps({"error": "no force", "refusals": {str(k): v for k, v in refusals.items()},
                                  "forged_forces": forged}))
            return 3 if refusals else 1
        send_pose(time.monotonic_ns(), t0)
        receive(time.monotonic_ns() + 10_000_000)
    warmup = (seq, forces)
    sent.clear()
    echoed.clear()
    lat_us.clear()
    up_us.clear()
    down_us.clear()
    forces = force_gaps = fading = limited = 0
    max_force = max_torque = 0.0

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
        "max_torque_Nm": max_torque,
        "forces_slew_limited": limited,
        "forged_forces": forged,
        "refusals": {str(k): v for k, v in refusals.items()},
        "protocol": a.protocol,
        "authenticated": key is not None,
        "late_ticks": late,
        "seconds": elapsed,
    }
    if trace:
        trace.close()
    if a.json:
        print(json.dumps(out))
    else:
        print(f"poses sent {out['poses_sent']} at {a.rate:.0f} Hz ({late} late), forces received {forces} "
              f"({out['forces_per_s']:.1f}/s, {force_gaps} seq gaps, {fading} fading), max |F| {max_force:.3f} N, "
              f"max |tau| {max_torque:.4f} N·m; protocol {a.protocol}, "
              f"{'authenticated' if key is not None else 'NOT authenticated'}")
        print(f"pose-to-force over {len(lat_us)} poses: p50 {q(0.5):.0f} us, p99 {q(0.99):.0f} us, "
              f"max {out['pose_to_force_us_max']:.0f} us")
        print(f"  of which pose -> the servo tick that used it: p50 {q(0.5, up_us):.0f} us, p99 {q(0.99, up_us):.0f} us; "
              f"servo -> driver: p50 {q(0.5, down_us):.0f} us, p99 {q(0.99, down_us):.0f} us (same machine only)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
