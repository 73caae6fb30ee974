"""`companion replay` on a real `companion fly` run folder: the stand-in ArduCopter flies the tracking
mission, then every logged cycle is fed back through a fresh decision core built from the params in the
log header, and must come out equal (exit 0). An edited copy of the same log must not (exit 1).

The fly shell adds its own fields to each record (commands, link events, telemetry, the shell's events and
actions); replay compares only what the core computed, so this checks that the flight's records are exactly
the core's output for the logged observations.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from test_companion_fly import assert_mission_completed, fly_mission

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
