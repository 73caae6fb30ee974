"""pymavlink reads the .tlog that companion's TlogWriter writes (the format MAVProxy,
pymavlink and UAVLogViewer use: 8-byte big-endian microseconds, then the raw MAVLink frame)."""
import os
import subprocess

from helpers import companion_fly_cmd
from pymavlink import mavutil


def test_pymavlink_reads_companion_tlog(tmp_path):
    # The testkit's sample writer, built beside the companion binary (`cargo build --bins`).
    exe = os.path.join(os.path.dirname(os.environ["COMPANION_BIN"]), "companion-tlog-sample")
    path = tmp_path / "flight.tlog"
    n = 20
    out = subprocess.run([exe, str(path), "--frames", str(n)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    msgs = []
    while True:
        m = conn.recv_match(blocking=False)
        if m is None:
            break
        if m.get_type() == "BAD_DATA":
            raise AssertionError(f"pymavlink could not parse a frame: {m}")
        msgs.append(m)
    assert len(msgs) == n
    for k, m in enumerate(msgs):
        # Timestamps come from the tlog's 8-byte prefix: 1.7e9 s + k * 0.1 s.
        assert abs(m._timestamp - (1_700_000_000 + k * 0.1)) < 1e-3, (k, m._timestamp)
        if k % 2 == 0:
            assert m.get_type() == "HEARTBEAT"
            assert m.custom_mode == k
            assert m.type == mavutil.mavlink.MAV_TYPE_QUADROTOR
        else:
            assert m.get_type() == "SYS_STATUS"
            assert m.battery_remaining == k
            assert m.voltage_battery == 12000


def _tlog_frames(path):
    """(t_us, frame bytes) entries of a .tlog, parsed here from the MAVLink header lengths (independent of
    the companion's reader): v2 = 10 + len + 2 (+13 signed), v1 = 6 + len + 2."""
    data = path.read_bytes()
    out, i = [], 0
    while i < len(data):
        t_us = int.from_bytes(data[i:i + 8], "big")
        stx, plen = data[i + 8], data[i + 9]
        if stx == 0xFD:
            n = 10 + plen + 2 + (13 if data[i + 10] & 0x01 else 0)
        else:
            assert stx == 0xFE, f"entry at {i}: not a MAVLink start byte: {stx:#x}"
            n = 6 + plen + 2
        out.append((t_us, data[i + 8:i + 8 + n]))
        i += 8 + n
    assert i == len(data), "the tlog ends inside an entry"
    return out


def test_flight_tlog_is_the_signed_wire(standin, tmp_path):
    """A signed `companion fly` run: every frame in flight.tlog is byte-identical to a frame on the wire (the
    stand-in's frames as it sent them, the companion's as the stand-in received them), signatures included,
    and pymavlink verifies every signature in the tlog with the key."""
    key = bytes(range(1, 33))
    sa = standin(signing_key=key, capture_wire=True, speedup=4.0)
    key_file = tmp_path / "signing.key"
    key_file.write_text(key.hex())
    log_dir = tmp_path / "runs"
    cmd = companion_fly_cmd(os.environ["COMPANION_BIN"], sa.url, log_dir, signing_key_file=key_file,
                            extra=["--duration", "6s"])
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    with sa.lock:
        wire = [(bytes(l.wire_out), bytes(l.wire_in)) for l in sa.wire_links]
    tlogs = list(log_dir.glob("*/flight.tlog"))
    assert len(tlogs) == 1, tlogs
    frames = _tlog_frames(tlogs[0])
    assert len(wire) == 1, "the companion connects once"
    from_standin, to_standin = wire[0]
    # source component: byte 6 of a v2 frame (STX len incompat compat seq sysid COMPID), 4 of a v1 frame
    ours = [f for _, f in frames if f[6 if f[0] == 0xFD else 4] == 191]
    theirs = [f for _, f in frames if f not in ours]
    assert len(theirs) > 20 and len(ours) > 3, (len(theirs), len(ours))
    for f in theirs:
        assert f[2] & 0x01, "the stand-in signs every frame"
        assert f in from_standin, f"received frame not on the wire as stored: {f.hex()}"
    for f in ours:
        assert f[2] & 0x01, "the companion signs every frame"
        assert f in to_standin, f"sent frame not on the wire as stored: {f.hex()}"
    stamps = [t for t, _ in frames]
    assert stamps == sorted(stamps)

    conn = mavutil.mavlink_connection(str(tlogs[0]), dialect="ardupilotmega")
    conn.setup_signing(key, sign_outgoing=False)
    n = 0
    while True:
        m = conn.recv_match(blocking=False)
        if m is None:
            break
        assert m.get_type() != "BAD_DATA", f"pymavlink rejected a tlog frame: {m}"
        assert m._signed, m
        n += 1
    assert n == len(frames)
