"""A companion restarted while the vehicle flies, against the stand-in ArduCopter (the real-SITL version, with
the route's own end, is test_real_restart.py): killed (SIGKILL, no stop path) while flying its route in AUTO and
started again with the same command line and --log-dir, it never says it waits for the operator; the ground
station hears `flight in progress` with the hand-off from component 191, the vehicle is put in RTL
(params/link.toml [flight] handoff), a MISSION_START is refused while the flight goes on, and the record says it
was not resumed."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from pathlib import Path
from typing import Any, Callable, Dict, List

import pytest

from helpers import joined_statustexts, offset, read_decision_log, wp
from standin.vocabulary import HOME_ALT_AMSL, HOME_LAT, HOME_LON
from standin import mavlink

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]

COMPANION = 191


def wait(pred: Callable[[], bool], timeout: float, what: str, run: Any = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return
        if run is not None and run.proc.poll() is not None:
            raise AssertionError(f"companion exited ({run.proc.returncode}) while waiting for {what}\n{run.output()}")
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout}s waiting for {what}" + (f"\n{run.output()}" if run else ""))


def texts_from_companion(gcs: Any, since: float) -> List[str]:
    """Chunks joined: one text each, as the ground station shows it."""
    return joined_statustexts(gcs.since(since, "STATUSTEXT"), COMPANION)


def test_restarted_in_the_air_says_a_flight_is_in_progress_and_hands_off(autopilot_factory, fly, client):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    first = fly(ap)                                        # --auto-start, as the real tests fly
    wait(lambda: sa.state()["mode"] == "AUTO" and sa.state()["alt"] > 10.0, 90, "the route in AUTO", first)
    first.proc.kill()
    first.proc.wait(timeout=10)
    time.sleep(1.0)
    assert sa.state()["armed"] and sa.state()["mode"] == "AUTO"
    t0 = time.monotonic()
    again = fly(ap, log_dir=first.log_dir)                 # systemd's restart: same command line, same --log-dir
    wait(lambda: any("flight in progress" in t and "hand-off RTL" in t for t in texts_from_companion(gcs, t0)), 10,
         "STATUSTEXT 'flight in progress, hand-off RTL' from 191", again)
    wait(lambda: sa.state()["mode"] == "RTL", 10, "the hand-off mode RTL", again)
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_DENIED, "a start was taken while the found flight goes on"
    time.sleep(2.0)
    said = texts_from_companion(gcs, t0)
    assert not [t for t in said if "waiting for the operator" in t], said
    again.proc.terminate()
    again.proc.wait(timeout=15)
    recs = again.records()
    evs = [e for r in recs for e in r.get("events", [])]
    assert any(e.startswith("started in flight") and "mode AUTO" in e and "hand-off RTL" in e and "not resumed" in e
               for e in evs), evs[:20]
    assert any(r.get("vehicle", {}).get("operator") == "flight_in_progress" for r in recs)


# ------------------------------------------------------------------------------------------------
# params/link.toml [flight] restart_in_air = "resume_with_consent": the companion's own run log proves the flight
# is its own (killed, same autopilot, recent, route uploaded), the autopilot's mission is that route, and the
# guarantee fits with the battery now; then a MISSION_START within 20 s resumes it, else it hands off.
# ------------------------------------------------------------------------------------------------

def resume_params(tmp_path: Path) -> Path:
    params = tmp_path / "params-resume"
    shutil.copytree(Path(__file__).parent.parent / "params", params)
    link = params / "link.toml"
    text = link.read_text()
    assert 'restart_in_air = "handoff"' in text
    link.write_text(text.replace('restart_in_air = "handoff"', 'restart_in_air = "resume_with_consent"'))
    return params


def run_records(log_dir: Path) -> List[Dict[str, Any]]:
    """Records of the newest run folder only (the restarted run's)."""
    newest = max((d for d in log_dir.iterdir() if (d / "decisions.jsonl").is_file()), key=lambda d: d.name)
    return read_decision_log(newest)


def killed_in_auto(autopilot_factory, fly, client, tmp_path):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    params = resume_params(tmp_path)
    first = fly(ap, extra=("--params", str(params)))
    # As the case: in AUTO past waypoint 2 (the run's records of its verified upload are written by then).
    wait(lambda: sa.state()["mode"] == "AUTO" and sa.state()["mission_current"] >= 3, 120, "the route in AUTO past "
         "waypoint 2", first)
    first.proc.kill()
    first.proc.wait(timeout=10)
    return ap, sa, gcs, params, first


def review_summary(run_dir: Path) -> str:
    out = subprocess.run([os.environ["COMPANION_BIN"], "review", str(run_dir), "--summary"], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout


def newest_run(log_dir: Path) -> Path:
    return max((d for d in log_dir.iterdir() if (d / "decisions.jsonl").is_file()), key=lambda d: d.name)


def test_restarted_in_the_air_resumes_its_own_flight_on_the_operators_consent(autopilot_factory, fly, client,
                                                                               tmp_path):
    ap, sa, gcs, params, first = killed_in_auto(autopilot_factory, fly, client, tmp_path)
    t0 = time.monotonic()
    again = fly(ap, log_dir=first.log_dir, extra=("--params", str(params)))
    wait(lambda: any("MISSION_START in 20s resumes" in t for t in texts_from_companion(gcs, t0)), 30,
         "the offer to resume from 191", again)
    assert sa.state()["mode"] == "AUTO", "handed off before the operator answered"
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    wait(lambda: any("resumed its own flight" in t for t in texts_from_companion(gcs, t0)), 10, "'resumed'", again)
    # The companion flies the rest and lands (--once: it exits after the landing, as the first run would have).
    rc = again.wait_exit(240)
    assert rc == 0, again.output()
    assert not sa.state()["armed"]
    said = texts_from_companion(gcs, t0)
    assert not [t for t in said if "hand-off" in t and "MISSION_START" not in t], said
    assert not [t for t in said if "waiting for the operator" in t and "landed" not in t], said
    recs = run_records(first.log_dir)
    evs = [e for r in recs for e in r.get("events", [])]
    resumed = [e for e in evs if e.startswith("started in flight: resumed on the operator's consent")]
    assert resumed and "died" in resumed[0] and "mission is the route" in resumed[0] \
        and "guarantee fits" in resumed[0], evs[:30]
    assert any(r.get("vehicle", {}).get("operator") == "started" for r in recs)
    # No arming, take-off or upload after the restart: the route's resume in AUTO only, then the landing.
    cmds = [c for r in recs for c in r.get("commands", [])]
    assert not [c for c in cmds if c["command"] in ("MAV_CMD_COMPONENT_ARM_DISARM", "MAV_CMD_NAV_TAKEOFF",
                                                     "MISSION_UPLOAD")], cmds
    assert recs[-1]["state"] == "landing" or not recs[-1]["vehicle"].get("armed", True)
    summary = review_summary(newest_run(first.log_dir))
    assert "started in flight, resumed on the operator's consent" in summary, summary


def test_restarted_in_the_air_without_consent_hands_off(autopilot_factory, fly, client, tmp_path):
    ap, sa, gcs, params, first = killed_in_auto(autopilot_factory, fly, client, tmp_path)
    t0 = time.monotonic()
    again = fly(ap, log_dir=first.log_dir, extra=("--params", str(params)))
    wait(lambda: any("MISSION_START in 20s resumes" in t for t in texts_from_companion(gcs, t0)), 30,
         "the offer to resume from 191", again)
    offered = time.monotonic()
    wait(lambda: sa.state()["mode"] == "RTL", 40, "the hand-off RTL once the consent window passed", again)
    assert time.monotonic() - offered > 15.0, "handed off before the consent window passed"
    # The companion sends the hand-off mode before the words saying why (restart.rs `hand_off`: the mode command,
    # then `say_found`, whose STATUSTEXT the rate limit may hold back): wait for the words too.
    wait(lambda: any("not resumed: no consent" in t for t in texts_from_companion(gcs, t0)), 5,
         "the STATUSTEXT 'not resumed: no consent' from 191", again)
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_DENIED, "a start was taken after the hand-off"
    again.proc.terminate()
    again.proc.wait(timeout=15)
    evs = [e for r in run_records(first.log_dir) for e in r.get("events", [])]
    assert any(e.startswith("started in flight") and "handed off: hand-off RTL" in e
               and "not resumed: no MISSION_START from the operator within 20 s" in e for e in evs), evs[:30]
    summary = review_summary(newest_run(first.log_dir))
    assert "started in flight, handed off (no MISSION_START" in summary, summary


def test_restarted_in_the_air_with_a_log_too_old_hands_off_with_the_reason(autopilot_factory, fly, client,
                                                                            tmp_path):
    ap, sa, gcs, params, first = killed_in_auto(autopilot_factory, fly, client, tmp_path)
    # The run log as a companion dead for ten minutes left it: every record 600 s older.
    log = newest_run(first.log_dir) / "decisions.jsonl"
    lines = []
    for line in log.read_text().splitlines():
        rec = json.loads(line)
        if "utc_us" in rec:
            rec["utc_us"] -= 600_000_000
        lines.append(json.dumps(rec))
    log.write_text("\n".join(lines) + "\n")
    t0 = time.monotonic()
    again = fly(ap, log_dir=first.log_dir, extra=("--params", str(params)))
    wait(lambda: sa.state()["mode"] == "RTL", 10, "the hand-off RTL at once", again)
    wait(lambda: any("not resumed: log too old" in t for t in texts_from_companion(gcs, t0)), 5, "the reason", again)
    said = texts_from_companion(gcs, t0)
    assert not [t for t in said if "resumes" in t], said
    again.proc.terminate()
    again.proc.wait(timeout=15)
    evs = [e for r in run_records(first.log_dir) for e in r.get("events", [])]
    assert any(e.startswith("started in flight") and "handed off" in e and "s old (more than 120 s)" in e
               for e in evs), evs[:30]


def test_restarted_in_the_air_with_the_mission_changed_hands_off_with_the_reason(autopilot_factory, fly, client,
                                                                                  tmp_path):
    ap, sa, gcs, params, first = killed_in_auto(autopilot_factory, fly, client, tmp_path)
    # Someone else's mission on the autopilot: one waypoint 30 m north, then RTL.
    gcs.target = (1, 1)
    items = [wp(HOME_LAT, HOME_LON, HOME_ALT_AMSL, frame=mavlink.MAV_FRAME_GLOBAL),
             wp(*offset(HOME_LAT, HOME_LON, 30.0, 0.0), 20.0, frame=mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT),
             wp(0, 0, 0, command=mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT)]
    assert gcs.upload_mission(items).type == mavlink.MAV_MISSION_ACCEPTED
    t0 = time.monotonic()
    again = fly(ap, log_dir=first.log_dir, extra=("--params", str(params)))
    wait(lambda: any("not resumed: mission changed" in t for t in texts_from_companion(gcs, t0)), 30, "the reason",
         again)
    wait(lambda: sa.state()["mode"] == "RTL", 10, "the hand-off RTL", again)
    again.proc.terminate()
    again.proc.wait(timeout=15)
    evs = [e for r in run_records(first.log_dir) for e in r.get("events", [])]
    assert any(e.startswith("started in flight") and "handed off" in e and "mission is not the route" in e
               for e in evs), evs[:30]
