"""The real-autopilot fixtures themselves, without an autopilot: the relay blacks out, cuts and injects as the
link tests rely on; the SITL finder says how to get one; instance numbers never repeat within a worker."""
from __future__ import annotations

import os
import socket
import threading
import time

import pytest

import real_autopilot
from real_autopilot import find_arducopter, next_instance
from relay import Relay, mavlink


class Upstream:
    """A one-client TCP server standing in for the autopilot's port: keeps what it receives, sends on demand."""

    def __init__(self) -> None:
        self.srv = socket.socket()
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind(("127.0.0.1", 0))
        self.srv.listen(4)
        self.port = self.srv.getsockname()[1]
        self.conns = []
        self.got = bytearray()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                c, _ = self.srv.accept()
            except OSError:
                return
            self.conns.append(c)
            threading.Thread(target=self._read, args=(c,), daemon=True).start()

    def _read(self, c: socket.socket) -> None:
        while True:
            try:
                d = c.recv(4096)
            except OSError:
                return
            if not d:
                return
            self.got += d

    def close(self) -> None:
        self.srv.close()
        for c in self.conns:
            c.close()


def wait_for(cond, timeout=3.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.02)
    return False


def frame(msg) -> bytes:
    return bytes(msg.pack(mavlink.MAVLink(None, srcSystem=1, srcComponent=191)))


@pytest.fixture
def upstream():
    u = Upstream()
    yield u
    u.close()


def test_relay_blackout_drops_both_ways_and_records_what_the_companion_sent(upstream):
    r = Relay(upstream.port).start()
    try:
        c = socket.create_connection(("127.0.0.1", r.port))
        c.settimeout(0.5)
        assert wait_for(lambda: upstream.conns)
        hb = frame(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 0, 3))
        c.sendall(hb)
        assert wait_for(lambda: len(upstream.got) == len(hb))
        start, end = r.blackout(1.0)
        land = frame(mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0))
        c.sendall(land)
        upstream.conns[0].sendall(hb)
        time.sleep(0.3)
        assert len(upstream.got) == len(hb), "bytes crossed the relay during the blackout"
        with pytest.raises(socket.timeout):
            c.recv(100)
        lost = r.sent_between(start, end, {"COMMAND_LONG"})
        assert [m.command for m in lost] == [mavlink.MAV_CMD_NAV_LAND]
        assert [d for (_, m, d) in r.sent if m.get_type() == "COMMAND_LONG"] == [False]
        time.sleep(end - time.monotonic() + 0.05)
        c.sendall(hb)
        assert wait_for(lambda: len(upstream.got) == 2 * len(hb)), "the link did not come back after the blackout"
        c.close()
    finally:
        r.stop()


def test_relay_cut_closes_the_connection_and_accepts_a_new_one(upstream):
    r = Relay(upstream.port).start()
    try:
        c = socket.create_connection(("127.0.0.1", r.port))
        assert wait_for(lambda: r.accepts == 1)
        r.cut()
        c.settimeout(2)
        assert c.recv(10) == b"", "the companion's connection stayed open after the cut"
        c2 = socket.create_connection(("127.0.0.1", r.port))
        assert wait_for(lambda: r.accepts == 2)
        c2.close()
        c.close()
    finally:
        r.stop()


def test_relay_injects_garbage_and_unsigned_frames_towards_the_companion(upstream):
    r = Relay(upstream.port).start()
    try:
        c = socket.create_connection(("127.0.0.1", r.port))
        c.settimeout(1)
        assert wait_for(lambda: r.accepts == 1)
        hb_len = len(frame(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 0, 3)))
        r.inject_garbage(40)
        data = b""
        while len(data) < 40 + hb_len:
            data += c.recv(4096)
        # neither the random bytes nor the CRC-broken heartbeat parse as a message
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        assert not [m for m in parser.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]
        r.inject_unsigned(mavlink.MAVLink_named_value_float_message(0, b"tgt_spd", 25.0), srccomp=100)
        time.sleep(0.2)
        msgs = mavlink.MAVLink(None).parse_buffer(c.recv(4096)) or []
        assert [(m.get_type(), m.get_srcComponent(), m.get_signed()) for m in msgs] == [("NAMED_VALUE_FLOAT", 100, False)]
        assert r.garbage_bytes == 40 and r.malformed_frames == 1
        c.close()
    finally:
        r.stop()


def test_without_an_arducopter_the_skip_says_how_to_get_one(monkeypatch, tmp_path):
    monkeypatch.setenv("ARDUCOPTER_BIN", str(tmp_path / "arducopter"))
    monkeypatch.delenv("SITL_DEFAULTS", raising=False)
    binary, defaults, why = find_arducopter()
    assert binary is None and "ARDUCOPTER_BIN" in why and "docs/sitl.md" in why and str(tmp_path) in why
    fake = tmp_path / "arducopter"
    fake.write_text("#!/bin/sh\n")
    fake.chmod(0o755)
    binary, defaults, why = find_arducopter()
    assert binary is None and "SITL_DEFAULTS" in why


def test_instance_numbers_differ_per_test_and_per_worker(monkeypatch):
    monkeypatch.setattr(real_autopilot, "_instance_counter", 0)
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw1")
    mine = [next_instance() for _ in range(3)]
    monkeypatch.setattr(real_autopilot, "_instance_counter", 0)
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw2")
    theirs = [next_instance() for _ in range(3)]
    assert len(set(mine)) == 3 and not set(mine) & set(theirs), (mine, theirs)
