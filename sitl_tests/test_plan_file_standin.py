"""`companion fly --mission FILE` with an operator's QGroundControl `.plan` or WPL 110 file (issue 36), on the
stand-in autopilot: the file's items are what the companion uploads (told by content, not by extension), a mission
that does not end the flight gets the route's end (RTL: a dead companion never leaves the vehicle hovering), the
guarantee judges the activities derived from that file, and the record follows them by MISSION_CURRENT and the
position; a malformed file is refused at start with file, item and reason, before any socket."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any, Dict, List

import os
import pytest

from helpers import offset
from standin import mavlink
from standin.vocabulary import HOME_LAT, HOME_LON
from test_autopilot_mission import companion_uploads
from test_operator_and_landing import wait

pytestmark = [pytest.mark.companion_fly]


def plan_file(items: List[Dict[str, Any]]) -> str:
    return json.dumps({"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
                       "mission": {"plannedHomePosition": [HOME_LAT, HOME_LON, 584.0], "items": items}})


def item(command: int, lat: float = 0.0, lon: float = 0.0, alt: float = 0.0, frame: int = 3,
         p1: float = 0.0, p2: float = 0.0) -> Dict[str, Any]:
    return {"type": "SimpleItem", "command": command, "frame": frame, "autoContinue": True,
            "params": [p1, p2, -1 if command == 178 else 0, None, lat, lon, alt]}


def operator_items() -> List[Dict[str, Any]]:
    """Take-off to 20 m, DO_CHANGE_SPEED 7 m/s, two waypoints; no RTL: the companion ends it."""
    a = offset(HOME_LAT, HOME_LON, 120.0, 0.0)
    b = offset(HOME_LAT, HOME_LON, 120.0, 80.0)
    return [item(22, alt=20.0), item(178, frame=2, p1=1.0, p2=7.0),
            item(16, *a, alt=20.0), item(16, *b, alt=25.0)]


def walked(records: List[Dict[str, Any]]) -> List[str]:
    out: List[str] = []
    for r in records:
        name = (r.get("guarantee") or {}).get("activity_name")
        if name and (not out or out[-1] != name):
            out.append(name)
    return out


def header(run: Any) -> Dict[str, Any]:
    logs = sorted(run.log_dir.rglob("decisions.jsonl"))
    assert logs, "no decision log\n" + run.output()
    return json.loads(logs[0].read_text().splitlines()[0])


def test_a_plan_file_is_uploaded_as_given_ended_by_rtl_and_followed(autopilot_factory, fly, tmp_path):
    ap = autopilot_factory()
    sa = ap.standin
    if sa is None:
        pytest.skip("stand-in only")
    mission = tmp_path / "survey.txt"          # no .plan extension: the kind is told by content
    mission.write_text(plan_file(operator_items()))
    run = fly(ap, mission=mission)             # --auto-start --once
    wait(lambda: run.proc.poll() is not None, 240, "the flight to end (--once)")
    assert run.proc.returncode == 0, run.output()
    ups = companion_uploads(sa)
    assert ups, "the companion uploaded nothing\n" + run.output()
    done = [e for e in sa.rec.of("mission_upload") if e.data["src"][1] == 191]
    assert done, "no completed upload"
    items = done[-1].data["items"]
    cmds = [it["command"] for it in items]
    assert cmds == [mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_DO_CHANGE_SPEED,
                    mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_WAYPOINT,
                    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH], items
    assert items[2]["param2"] == pytest.approx(7.0), items[2]
    assert items[4]["z"] == pytest.approx(25.0), items[4]
    plan = header(run).get("plan")
    assert plan and plan["route_file"].endswith("survey.txt"), plan
    derived = [a["name"] for a in plan["derived"]]
    assert derived == ["take_off", "leghome-2", "leg2-3", "return", "land"], derived
    assert [a["speed_mps"] for a in plan["derived"]][1:3] == [7.0, 7.0], "DO_CHANGE_SPEED plans the legs after it"
    seen = walked(run.records())
    assert set(seen) <= set(derived), (seen, derived)
    order = [derived.index(a) for a in seen]
    assert order == sorted(order), seen
    assert {"leghome-2", "leg2-3", "return"} <= set(seen), seen
    assert sa.state()["armed"] is False


def test_a_malformed_plan_or_wpl_file_refuses_the_start_naming_file_item_and_reason(tmp_path):
    exe = os.environ["COMPANION_BIN"]
    bad_plan = operator_items()
    bad_plan[2] = item(17, *offset(HOME_LAT, HOME_LON, 120.0, 0.0), alt=20.0)      # LOITER_UNLIM
    cases = {
        "bad.plan": (plan_file(bad_plan), ["bad.plan", "mission.items[2]", "LOITER_UNLIM"]),
        "bad.waypoints": ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t-35.36\t149.16\t584\t1\n"
                          "1\t0\t3\t16\t0\t0\t0\t0\tnorth\t149.16\t20\t1\n",
                          ["bad.waypoints", "line 3", "expected a number"]),
    }
    for name, (text, words) in cases.items():
        f = tmp_path / name
        f.write_text(text)
        # Nothing listens there: the refusal comes before any socket.
        out = subprocess.run([exe, "fly", "--connect", "udpout:127.0.0.1:9", "--mission", str(f),
                              "--log-dir", str(tmp_path / "logs"), "--once"],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode != 0, out
        for w in words:
            assert w in out.stderr, (w, out.stderr)
