"""`fly --live` and `simulate --live`: a Foxglove WebSocket client (ws-protocol v1, the `websockets` package)
receives every decision record of the run on the same channels as `export --format mcap` (read back with the
`mcap` package, an independent reader), and a viewer that never reads loses messages (counted) without changing
the records.

Stand-in only (no real autopilot): the protocol and the queues are the companion's, not the autopilot's.
"""
from __future__ import annotations

import asyncio
import json
import os
import re
import socket
import struct
import subprocess
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Dict, List, Optional, Tuple

import pytest

mcap_reader = pytest.importorskip("mcap.reader", reason="pip install -r sitl_tests/requirements.txt (mcap)")
websockets = pytest.importorskip("websockets", reason="pip install -r sitl_tests/requirements.txt (websockets)")
from websockets.sync.client import connect as sync_connect  # noqa: E402

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]

SUBPROTOCOL = "foxglove.websocket.v1"
LIVE_LINE = re.compile(r"live: Foxglove WebSocket at (ws://\S+)")


def exe() -> str:
    return os.environ["COMPANION_BIN"]


def wait_live_url(stderr_path: Path, proc: subprocess.Popen, timeout: float = 30.0) -> str:
    """The address the companion says it serves (stderr, at start)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        m = LIVE_LINE.search(stderr_path.read_text())
        if m:
            return m.group(1)
        assert proc.poll() is None, f"exited before serving: {stderr_path.read_text()[-2000:]}"
        time.sleep(0.05)
    raise AssertionError(f"no live address said on stderr: {stderr_path.read_text()[-2000:]}")


def wait_said_text(stderr_path: Path, proc: subprocess.Popen, text: str, timeout: float = 10.0) -> None:
    """Until the companion has said `text` on stderr (it must, while still running, before the timeout)."""
    deadline = time.monotonic() + timeout
    while text not in stderr_path.read_text():
        assert proc.poll() is None, f"exited without saying {text!r}: {stderr_path.read_text()[-2000:]}"
        assert time.monotonic() < deadline, f"{text!r} not said: {stderr_path.read_text()[-2000:]}"
        time.sleep(0.02)


class Viewer:
    """A Foxglove WebSocket client on its own thread: subscribes to every advertised channel and keeps each
    messageData (topic, log time ns, JSON) until the server closes."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.channels: List[Dict[str, Any]] = []
        self.server_info: Dict[str, Any] = {}
        self.messages: List[Tuple[str, int, Any]] = []
        self.subscribed = threading.Event()
        self.error: Optional[BaseException] = None
        self.thread = threading.Thread(target=lambda: asyncio.run(self._run()), daemon=True)

    def start(self) -> "Viewer":
        self.thread.start()
        assert self.subscribed.wait(20), f"viewer did not subscribe: {self.error!r}"
        return self

    async def _run(self) -> None:
        try:
            async with websockets.connect(self.url, subprotocols=[SUBPROTOCOL], max_size=None) as ws:
                assert ws.subprotocol == SUBPROTOCOL
                self.server_info = json.loads(await ws.recv())
                adv = json.loads(await ws.recv())
                assert self.server_info["op"] == "serverInfo" and adv["op"] == "advertise"
                self.channels = adv["channels"]
                topic_of = {100 + c["id"]: c["topic"] for c in self.channels}
                await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": sid, "channelId": sid - 100} for sid in topic_of]}))
                self.subscribed.set()
                async for frame in ws:
                    assert isinstance(frame, bytes), f"unexpected text after advertise: {frame[:200]}"
                    op, sid, t = struct.unpack_from("<BIQ", frame)
                    assert op == 1, f"opcode {op}"
                    self.messages.append((topic_of[sid], t, json.loads(frame[13:])))
        except websockets.ConnectionClosedOK:
            pass
        except BaseException as e:  # reported by join()
            self.error = e
            self.subscribed.set()

    def join(self, timeout: float = 30.0) -> None:
        self.thread.join(timeout)
        assert not self.thread.is_alive(), "the server did not close the viewer's connection"
        assert self.error is None, f"viewer failed: {self.error!r}"

    def by_topic(self) -> Dict[str, List[Tuple[int, Any]]]:
        out: Dict[str, List[Tuple[int, Any]]] = {}
        for topic, t, msg in self.messages:
            out.setdefault(topic, []).append((t, msg))
        return out


def stalled_viewer(url: str) -> Any:
    """A viewer that subscribes to everything and then never reads: a tiny receive buffer and a one-message
    client queue, so the server's sends block soon."""
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
    sock.connect((host, int(port)))
    ws = sync_connect(url, sock=sock, subprotocols=[SUBPROTOCOL], max_queue=1, max_size=None)
    json.loads(ws.recv())
    adv = json.loads(ws.recv())
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [
        {"id": c["id"], "channelId": c["id"]} for c in adv["channels"]]}))
    return ws


def run_folder(stdout: str) -> Path:
    m = re.search(r"run folder: (.+)", stdout)
    assert m, f"no run folder printed: {stdout[-1000:]}"
    return Path(m.group(1).strip())


def record_lines(run: Path) -> List[str]:
    """The record lines of decisions.jsonl as written (the header and end lines have no `cycle`)."""
    lines = (run / "decisions.jsonl").read_text().splitlines()
    return [ln for ln in lines if ln.startswith('{"cycle":')]


def mcap_by_topic(run: Path, tmp: Path) -> Dict[str, List[Tuple[int, Any]]]:
    """`companion export --format mcap` of the run, read with the `mcap` package."""
    out = tmp / f"{run.name}.mcap"
    subprocess.run([exe(), "export", str(run), "--format", "mcap", "--out", str(out)], check=True,
                   capture_output=True, timeout=60)
    got: Dict[str, List[Tuple[int, Any]]] = {}
    with open(out, "rb") as f:
        for _schema, channel, message in mcap_reader.make_reader(f).iter_messages():
            got.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data)))
    return got


def assert_live_equals_log(viewer: Viewer, run: Path, tmp: Path) -> List[Dict[str, Any]]:
    records = [json.loads(ln) for ln in record_lines(run)]
    assert records, "no record written"
    live = viewer.by_topic()
    exported = mcap_by_topic(run, tmp)
    decisions = {t: m for t, m in exported.items() if t.startswith("/decisions/")}
    # The channel list is the export's (its /mavlink/* channels come from the tlog after the flight).
    assert sorted(c["topic"] for c in viewer.channels) == sorted(decisions)
    assert sorted(live) == sorted(decisions)
    # Every record, on every channel, equal to the export of decisions.jsonl (message and log time).
    for topic, msgs in decisions.items():
        assert live[topic] == msgs, f"{topic}: live {len(live[topic])} messages, export {len(msgs)}"
    # And straight from decisions.jsonl: one summary per record, in order; the probabilities as logged.
    assert [m["cycle"] for _, m in live["/decisions/summary"]] == [r["cycle"] for r in records]
    for (_, m), r in zip(live["/decisions/probabilities"], records):
        assert {k: v for k, v in m.items() if k not in ("cycle", "time_s")} == r["probabilities"]
    return records


# ------------------------------------------------------------------------------------------------


def test_simulate_live_viewer_receives_every_record(tmp_path):
    err = tmp_path / "sim.err"
    proc = subprocess.Popen([exe(), "simulate", "--live", "ws://127.0.0.1:0", "--runs-dir", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=open(err, "w"), text=True)
    try:
        url = wait_live_url(err, proc)
        # Said on its own line, just after the address: a read between the two writes sees only the first.
        wait_said_text(err, proc, "waiting up to 30 s")
        viewer = Viewer(url).start()
        out, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err.read_text()[-2000:]
    viewer.join()
    records = assert_live_equals_log(viewer, run_folder(out), tmp_path)
    # The viewer subscribed before the first step: nothing lost, and the records say so.
    assert all(r["live_dropped"] == 0 for r in records)
    assert "live_dropped 0" in err.read_text()


def test_a_viewer_that_never_reads_loses_messages_not_records(tmp_path):
    plain = subprocess.run([exe(), "simulate", "--runs-dir", str(tmp_path / "plain")], capture_output=True,
                           text=True, timeout=120, check=True)
    err = tmp_path / "live.err"
    proc = subprocess.Popen([exe(), "simulate", "--live", "127.0.0.1:0", "--live-queue", "2",
                             "--runs-dir", str(tmp_path / "live")],
                            stdout=subprocess.PIPE, stderr=open(err, "w"), text=True)
    try:
        ws = stalled_viewer(wait_live_url(err, proc))
        out, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err.read_text()[-2000:]
    with_live = record_lines(run_folder(out))
    without = record_lines(run_folder(plain.stdout))
    # The field is only present with --live: removed, the lines are byte-identical.
    dropped = [int(re.search(r',"live_dropped":(\d+)', ln).group(1)) for ln in with_live]
    assert [re.sub(r',"live_dropped":\d+', "", ln) for ln in with_live] == without
    assert not any("live_dropped" in ln for ln in without)
    assert dropped == sorted(dropped) and dropped[-1] > 0, dropped
    total = int(re.search(r"live_dropped (\d+)", err.read_text()).group(1))
    assert total >= dropped[-1] > 0
    # The run's summary says it too.
    summary = subprocess.run([exe(), "review", str(run_folder(out)), "--summary"], capture_output=True, text=True,
                             timeout=60, check=True).stdout
    assert re.search(rf"live viewers lost +{dropped[-1]} messages", summary), summary


def test_fly_live_viewer_receives_every_record_of_a_standin_flight(tmp_path, standin, fly):
    # The viewer subscribes before the autopilot is there (no cycle runs without it), so it sees the whole run.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    ap = SimpleNamespace(url=f"tcp:127.0.0.1:{port}", signing_key=None)
    run = fly(ap, extra=("--live", "127.0.0.1:0", "--duration", "25s"))
    viewer = Viewer(wait_live_url(run.stderr_path, run.proc)).start()
    sa = standin(listen=f"tcp:127.0.0.1:{port}", speedup=4.0, ekf_ready_s=8.0)
    rc = run.wait_exit(90)
    assert rc == 0, run.output()
    viewer.join()
    assert sa.state()["armed"] or sa.rec.of("takeoff_complete"), "the stand-in never flew\n" + run.output()
    runs = [p for p in run.log_dir.iterdir() if (p / "decisions.jsonl").is_file()]
    assert len(runs) == 1, runs
    records = assert_live_equals_log(viewer, runs[0], tmp_path)
    assert len(records) >= 10, len(records)
    assert all(r["live_dropped"] == 0 for r in records)
    assert "live_dropped 0 live_ignored 0" in run.stderr_path.read_text()
