"""pymavlink reads the .tlog that companion's TlogWriter writes (the format MAVProxy,
pymavlink and UAVLogViewer use: 8-byte big-endian microseconds, then the raw MAVLink frame)."""
import os
import subprocess

from pymavlink import mavutil


def test_pymavlink_reads_companion_tlog(tmp_path):
    exe = os.environ["COMPANION_BIN"]
    path = tmp_path / "flight.tlog"
    n = 20
    out = subprocess.run([exe, "__tlog-sample", str(path), "--frames", str(n)], capture_output=True, text=True, timeout=60)
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
