"""`companion replay` on a real `companion fly` run folder: the stand-in ArduCopter flies the tracking
mission, then every logged cycle is fed back through a fresh decision core built from the params in the
log header, and must come out equal (exit 0). An edited copy of the same log must not (exit 1).

The fly shell adds its own fields to each record (commands, link events, telemetry, the shell's events and
actions); replay compares only what the core computed, so this checks that the flight's records are exactly
the core's output for the logged observations.
"""
from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from helpers import said
from standin_autopilot import mavlink
from test_companion_fly import assert_mission_completed, fly_mission
from test_learn_cpt_trust import free_udp_port
from test_operator_and_landing import COMPANION, short_route, stop, wait

NEW_FLIGHT_EVENT = "flight over: landed and disarmed; waiting for the operator"

pytestmark = pytest.mark.companion_fly


def run_folders(log_dir: Path) -> list:
    return sorted(p.parent for p in Path(log_dir).glob("*/decisions.jsonl"))


def replay(folder: Path) -> subprocess.CompletedProcess:
    return subprocess.run([os.environ["COMPANION_BIN"], "replay", str(folder)], capture_output=True, text=True,
                          timeout=300)


def test_standin_flight_replays_equal_in_every_cycle(autopilot_factory, fly, monitors_factory, tmp_path):
    ap = autopilot_factory()
    f = fly_mission(ap, fly, monitors_factory)
    assert_mission_completed(f)
    folders = run_folders(f.run.log_dir)
    assert len(folders) == 1, folders
    folder = folders[0]
    n = sum(1 for r in f.records if "kind" not in r)
    assert n > 5, n

    out = replay(folder)
    assert out.returncode == 0, f"{out.stdout}\n{out.stderr}"
    assert f"all {n} cycles equal" in out.stdout, out.stdout

    # The same flight with one chosen action changed is no longer the core's.
    edited = tmp_path / "edited"
    shutil.copytree(folder, edited)
    log = edited / "decisions.jsonl"
    lines = log.read_text().splitlines()
    idx = next(i for i, line in enumerate(lines)
               if "kind" not in json.loads(line) and json.loads(line).get("actions"))
    rec = json.loads(lines[idx])
    rec["actions"] = rec["actions"] + ["return_to_base"]
    lines[idx] = json.dumps(rec, separators=(",", ":"))
    log.write_text("\n".join(lines) + "\n")
    out = replay(edited)
    assert out.returncode == 1, f"{out.stdout}\n{out.stderr}"
    assert f"cycle {rec['cycle']} differs" in out.stdout and "actions" in out.stdout, out.stdout


def test_standin_flight_learning_cpt_rows_replays_equal(autopilot_factory, fly, monitors_factory, tmp_path):
    """`fly --learn-cpt`: the tracking steps the onboard tracker reports kept update the flown version's
    C_Vk row in flight (records carry `cpt_learned`, bounded by params/learning.toml), and replay re-derives
    every update from the log: all cycles equal. A logged count edited by hand is caught. The tracker speaks on
    a dedicated onboard link (loopback): on the unsigned autopilot link alone --learn-cpt is refused."""
    port = free_udp_port()
    ap = dataclasses.replace(autopilot_factory(), monitor_url=f"udpout:127.0.0.1:{port}")
    f = fly_mission(ap, fly, monitors_factory, extra=("--learn-cpt", "--onboard", f"udpin:127.0.0.1:{port}"))
    assert_mission_completed(f)
    learned = [(r["cycle"], u) for r in f.records if "kind" not in r for u in r.get("cpt_learned", [])]
    assert learned, "no CPT row learned in a flight that tracked"
    assert any(u["node"].startswith("C_V") for _, u in learned), learned
    for _, u in learned:
        assert 0.0 <= u["new"] <= 1.0 and abs(u["new"] - u["old"]) <= 0.6 + 1e-9, u
        assert u["trials"] >= u["successes"] >= 0, u
    # the row keeps moving over the flight: the last update's counts are the most
    last = learned[-1][1]
    assert last["trials"] >= learned[0][1]["trials"], learned
    folder = run_folders(f.run.log_dir)[0]
    out = replay(folder)
    n = sum(1 for r in f.records if "kind" not in r)
    assert out.returncode == 0, f"{out.stdout}\n{out.stderr}"
    assert f"all {n} cycles equal" in out.stdout, out.stdout

    edited = tmp_path / "edited-learning"
    shutil.copytree(folder, edited)
    log = edited / "decisions.jsonl"
    lines = log.read_text().splitlines()
    idx = next(i for i, line in enumerate(lines) if json.loads(line).get("cpt_learned"))
    rec = json.loads(lines[idx])
    rec["cpt_learned"][0]["trials"] += 7
    lines[idx] = json.dumps(rec, separators=(",", ":"))
    log.write_text("\n".join(lines) + "\n")
    out = replay(edited)
    assert out.returncode == 1 and "cpt_learned" in out.stdout, f"{out.stdout}\n{out.stderr}"


def test_two_flights_in_one_run_replay_equal_with_the_core_restarted_between(autopilot_factory, fly, client,
                                                                                tmp_path):
    """Without --once, fly starts a fresh core for the next flight: replay restarts its own at the record that
    says the flight was over, and only then does the second flight replay equal."""
    ap = autopilot_factory(speedup=2.0, ekf_ready_s=4.0)
    sa = ap.standin
    gcs = client(sa.url)
    run = fly(ap, mission=short_route(tmp_path), once=False)
    wait(lambda: sa.rec.of("arm") and not sa.state()["armed"] and sa.state()["landed"], 240, "the first landing", run)
    # the companion sees the landing and starts waiting for the operator: the start is taken from then on
    wait(lambda: any(NEW_FLIGHT_EVENT in r.get("events", []) for r in run.records()), 30,
         "the companion waiting for the operator again", run, poll=0.5)
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    wait(lambda: len(sa.rec.of("arm")) == 2 and sa.state()["alt"] > 5.0, 90, "the second take-off", run)
    time.sleep(2.0)
    stop(run)
    records = [r for r in run.records() if "kind" not in r]
    restarts = [i for i, r in enumerate(records) if NEW_FLIGHT_EVENT in r.get("events", [])]
    assert len(restarts) == 1 and 0 < restarts[0] < len(records) - 3, (restarts, len(records))
    folders = run_folders(run.log_dir)
    assert len(folders) == 1, folders

    out = replay(folders[0])
    assert out.returncode == 0, f"{out.stdout}\n{out.stderr}"
    assert f"all {len(records)} cycles equal" in out.stdout, out.stdout

    # Without the restart (the event edited out) the second flight is replayed on the first flight's core state
    # (the battery model carries over): it differs from the first record of the second flight.
    edited = tmp_path / "no-restart"
    shutil.copytree(folders[0], edited)
    log = edited / "decisions.jsonl"
    lines = log.read_text().splitlines()
    for i, line in enumerate(lines):
        rec = json.loads(line)
        if "kind" not in rec and NEW_FLIGHT_EVENT in [said(e) for e in rec.get("events", [])]:
            rec["events"] = [e for e in rec["events"] if said(e) != NEW_FLIGHT_EVENT]
            lines[i] = json.dumps(rec, separators=(",", ":"))
            cycle = rec["cycle"]
    log.write_text("\n".join(lines) + "\n")
    out = replay(edited)
    assert out.returncode == 1, f"{out.stdout}\n{out.stderr}"
    assert f"cycle {cycle} differs" in out.stdout, out.stdout
