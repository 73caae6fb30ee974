"""`companion review` renders a self-contained HTML report that a real browser draws with data.

The decision log is written here, in Python, by its own generator (independent of the Rust
writer): a mission shaped like the BFM paper's Table 4. Headless Chromium (Debian's `chromium`)
takes a screenshot to sitl_tests/artifacts/ and dumps the DOM, which is checked for one timeline
row per record, the Tables 4-7 phases, and plots whose polylines carry points.
"""
import json
import os
import shutil
import subprocess
import tempfile
from html.parser import HTMLParser
from pathlib import Path

import pytest

ARTIFACTS = Path(__file__).parent / "artifacts"

# (state, actions, resources summary, steps): Table 4 (scenario 1, vibrations, safety policy).
PLAN = [
    ("base", ["take_off"], "-", 1),
    ("wp1", ["follow_trajectory", "detect_obstacles_lidar"], "5 ms", 4),
    ("wpi", ["follow_trajectory", "detect_obstacles_lidar", "search_zone_t"], "5 + 394 ms", 4),
    ("wpf", ["follow_trajectory", "detect_obstacles_lidar", "search_zone_t", "detect_target"], "5 + 394 + 10 ms", 3),
    ("target", ["track_v3", "detect_obstacles_lidar", "search_zone_t"], "10 + 5 + 394 ms", 3),
    ("v3", ["track_v3", "avoid_obstacle", "search_zone_t"], "10 + 1 + 394 ms", 4),
    ("v3", ["track_v3", "detect_obstacles_lidar", "search_emergency_zone"], "10 + 5 + 255 ms", 6),
    ("v3", ["track_v1", "detect_obstacles_lidar", "search_emergency_zone"], "10 + 1 ms", 10),
    ("landing", ["land"], "-", 5),
]
PROBS = ["P_sys", "P_battery", "P_obs", "P_detect", "P_V3", "P_V1"]


def make_records():
    recs = []
    cycle = 0
    for phase, (state, actions, res, steps) in enumerate(PLAN):
        for k in range(steps):
            f = cycle / 40.0
            events = []
            if k == 0 and state == "wpf":
                events.append("target detected")
            if k == 0 and phase == 5:
                events.append("obstacle detected")
            if k == 0 and phase == 7:
                events.append("insufficient resources to execute V3")
            rec = {
                "cycle": cycle,
                "time_s": cycle * 0.5,
                "state": state,
                "events": events,
                "observations": {"vibration_mps2": 3.5, "lat_deg": 47.3977 + 0.0001 * cycle, "lon_deg": 8.5456 + 0.00005 * (cycle % 9)},
                "evidence": {},
                "probabilities": {p: round(0.5 + 0.4 * ((i + cycle) % 7) / 7, 3) for i, p in enumerate(PROBS)},
                "proposals": [],
                "conflicts": ([{"kept": "avoid_obstacle", "dropped": ["follow_trajectory"], "rule": "safety"}] if phase == 5 else []),
                "actions": actions,
                "resources": {
                    "placements": [],
                    "cpu_load": 0.2 + 0.6 * f,
                    "tiles_used": min(4, len(actions) - 1),
                    "reconfigurations": 0,
                    "degraded": (["tracking V3 -> V1: insufficient resources"] if (k == 0 and phase == 7) else []),
                    "dropped": [],
                    "summary": res,
                },
                "guarantee": {
                    "activity": 0,
                    "activity_name": "track",
                    "margins": {"energy_j": 20000.0 - 300.0 * cycle, "duration_s": 300.0 - 4.0 * cycle},
                    "goals": {"energy_j": 60000.0, "duration_s": 900.0},
                    "drift": {},
                    "reallocation": None,
                    "infeasible": False,
                },
                "commands": [],
                "link_events": (["FAILSAFE: GCS link lost"] if cycle == 30 else []),
                "vehicle": {
                    "altitude_m": 0.0 if state in ("base",) else (max(0.0, 20.0 - 5.0 * k) if state == "landing" else 20.0),
                    "battery_pct": 100.0 - 1.2 * cycle,
                    "mode": "LAND" if state == "landing" else "GUIDED",
                },
            }
            if cycle == 0:
                rec["commands"].append({"action": "take_off", "command": "MAV_CMD_NAV_TAKEOFF", "result": "ACCEPTED", "attempts": 1, "latency_ms": 140.0})
            if state == "landing" and k == 0:
                rec["commands"].append({"action": "land", "command": "MAV_CMD_NAV_LAND", "result": "DENIED", "attempts": 1, "latency_ms": 60.0})
                rec["commands"].append({"action": "land", "command": "SET_MODE LAND", "result": "ACCEPTED", "attempts": 2, "latency_ms": 310.0})
            recs.append(rec)
            cycle += 1
    return recs


def write_run(run: Path, recs):
    run.mkdir(parents=True)
    header = {"schema": 1, "kind": "header", "started_utc": "2025-06-01T12:00:00Z", "git_revision": "test",
              "command": "companion simulate --policy safety --seed 7", "params": {"policies.toml": "[safety]\n"}, "step_s": 0.5}
    with open(run / "decisions.jsonl", "w") as f:
        f.write(json.dumps(header) + "\n")
        for r in recs:
            f.write(json.dumps(r) + "\n")
        f.write(json.dumps({"kind": "event", "cycle": 12, "time_s": 6.0, "event": "mode change requested"}) + "\n")
        f.write(json.dumps({"kind": "end", "records": len(recs), "events": 1, "dropped": 0}) + "\n")


class DomCounter(HTMLParser):
    """Collects what the checks need from the browser's DOM."""

    def __init__(self):
        super().__init__()
        self.timeline_rows = []
        self.phase_rows = []
        self.figures = {}
        self.current_figure = None
        self.summary = {}
        self.command_rows = 0
        self.failed_command_rows = 0
        self.command_categories = []
        self.why_cycles = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        cls = (a.get("class") or "").split()
        if tag == "tr" and "timeline-row" in cls:
            self.timeline_rows.append(a)
        if tag == "tr" and "phase-row" in cls:
            self.phase_rows.append(a)
        if tag == "tr" and "command-row" in cls:
            self.command_rows += 1
            self.failed_command_rows += "failed" in cls
            self.command_categories.append(a.get("data-category"))
        if tag == "details" and "why" in cls:
            self.why_cycles.append(int(a["data-cycle"]))
        if tag == "figure" and "plot" in cls:
            self.current_figure = a.get("id")
            self.figures[self.current_figure] = {"attrs": a, "polylines": []}
        if tag == "polyline" and self.current_figure:
            self.figures[self.current_figure]["polylines"].append(a)
        if tag == "section" and a.get("id") == "summary":
            self.summary = a

    def handle_endtag(self, tag):
        if tag == "figure":
            self.current_figure = None


def chromium():
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    pytest.fail("chromium not found: scripts/test.sh installs it (apt-get install -y chromium)")


def run_chromium(args, url):
    with tempfile.TemporaryDirectory() as profile:
        cmd = [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
               "--disable-background-networking", "--disable-component-update", "--disable-sync",
               f"--user-data-dir={profile}", *args, url]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=180)


def tracking_steps(recs):
    """The shared definition (companion-core/src/tracking.rs), written here again: a cycle at the
    target or in a tracking phase that chooses track_vN and is in phase vN at the next record."""
    n = 0
    for r, nxt in zip(recs, recs[1:]):
        tracking_phase = len(r["state"]) == 2 and r["state"][0] == "v" and r["state"][1].isdigit()
        if r["state"] != "target" and not tracking_phase:
            continue
        v = next((a[len("track_v"):] for a in r["actions"] if a.startswith("track_v")), None)
        if v is not None and nxt["state"] == "v" + v:
            n += 1
    return n


def expected_phases(recs):
    phases = []
    for r in recs:
        key = (r["state"], tuple(r["actions"]))
        if not phases or phases[-1][0] != key:
            phases.append([key, 0])
        phases[-1][1] += 1
    return phases


def test_review_report_renders_in_chromium(tmp_path):
    exe = os.environ["COMPANION_BIN"]
    recs = make_records()
    run = tmp_path / "runs" / "2025-06-01T12-00-00Z"
    write_run(run, recs)
    out = subprocess.run([exe, "review", str(run)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    report = run / "report.html"
    assert report.exists()
    html = report.read_text()
    assert "<script" not in html and "<link" not in html, "report must be self-contained"
    # The map of the flown track: one point per record position, drawn inline.
    assert f'id="map" data-points="{len(recs)}"' in html
    # The event line written after the last record lands on its cycle (12).
    assert 'data-cycle="12" data-state="target" data-actions="3" data-events="1"' in html

    ARTIFACTS.mkdir(exist_ok=True)
    shot = ARTIFACTS / "review_report.png"
    if shot.exists():
        shot.unlink()
    url = report.resolve().as_uri()
    s = run_chromium([f"--screenshot={shot}", "--window-size=1400,2600", "--hide-scrollbars"], url)
    assert shot.exists(), s.stderr[-2000:]
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    d = run_chromium(["--dump-dom"], url)
    assert d.returncode == 0, d.stderr[-2000:]
    dom = DomCounter()
    dom.feed(d.stdout)

    # One timeline row per record, in order, with the record's state.
    assert len(dom.timeline_rows) == len(recs)
    assert [int(r["data-cycle"]) for r in dom.timeline_rows] == [r["cycle"] for r in recs]
    assert [r["data-state"] for r in dom.timeline_rows] == [r["state"] for r in recs]
    # Tables 4-7 shape: one phase row per run of equal (state, action set).
    phases = expected_phases(recs)
    assert len(dom.phase_rows) == len(phases) == len(PLAN)
    assert [int(p["data-records"]) for p in dom.phase_rows] == [n for _, n in phases]
    # The failsafe at cycle 30 and the mode change GUIDED -> LAND are marked.
    assert "failsafe" in dom.timeline_rows[30]["class"].split()
    first_landing = next(i for i, r in enumerate(recs) if r["state"] == "landing")
    assert "mode-change" in dom.timeline_rows[first_landing]["class"].split()

    # Plots drawn with data: polylines whose points attribute holds one pair per record.
    for pid in ["plot-probabilities", "plot-margin-energy_j", "plot-margin-duration_s", "plot-cpu-load",
                "plot-fpga-tiles", "plot-altitude", "plot-battery"]:
        assert pid in dom.figures, f"{pid} missing"
        lines = dom.figures[pid]["polylines"]
        assert lines, f"{pid} has no polyline"
        for pl in lines:
            pairs = pl["points"].split()
            assert len(pairs) == len(recs), (pid, pl.get("data-series"), len(pairs))
            assert all(len(p.split(",")) == 2 for p in pairs)
    assert len(dom.figures["plot-probabilities"]["polylines"]) == len(PROBS)
    # Altitude: higher altitude is drawn higher (smaller SVG y) — the plot is not upside down.
    alt = [float(p.split(",")[1]) for p in dom.figures["plot-altitude"]["polylines"][0]["points"].split()]
    assert alt[0] > alt[5]  # 0 m at base, 20 m at wp1

    # Summary numbers, counted here from the records.
    assert int(dom.summary["data-tracking-steps"]) == tracking_steps(recs) == 11
    assert int(dom.summary["data-conflicts"]) == sum(len(r["conflicts"]) for r in recs)
    assert int(dom.summary["data-degradations"]) == 1
    # The one DENIED command is denied, not failed; nothing failed.
    assert int(dom.summary["data-failed-commands"]) == 0
    assert int(dom.summary["data-commands-denied"]) == 1
    assert dom.command_rows == 3 and dom.failed_command_rows == 0
    assert sorted(dom.command_categories) == ["accepted", "accepted", "denied"]
    # A why for every cycle.
    assert dom.why_cycles == [r["cycle"] for r in recs]


def test_review_summary_in_terminal_has_no_colour_when_piped(tmp_path):
    exe = os.environ["COMPANION_BIN"]
    recs = make_records()
    run = tmp_path / "run"
    write_run(run, recs)
    out = subprocess.run([exe, "review", str(run), "--summary"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "\x1b[" not in out.stdout
    tracking = tracking_steps(recs)
    assert f"{tracking} steps / {tracking * 0.5:.2f} s" in out.stdout
    for state, *_ in PLAN:
        assert state in out.stdout
    assert not (run / "report.html").exists()  # --summary alone writes no HTML


def test_review_of_empty_log_fails_with_a_clear_message(tmp_path):
    exe = os.environ["COMPANION_BIN"]
    log = tmp_path / "decisions.jsonl"
    log.write_text("")
    out = subprocess.run([exe, "review", str(log)], capture_output=True, text=True, timeout=60)
    assert out.returncode != 0
    assert "empty" in out.stderr


@pytest.mark.parametrize("scenario,seed", [("complete-1", 1), ("vibrations", 4), ("wind", 2)])
def test_tracking_time_equal_in_simulate_and_review(tmp_path, scenario, seed):
    exe = os.environ["COMPANION_BIN"]
    sim = subprocess.run([exe, "simulate", "--json", "--scenario", scenario, "--seed", str(seed),
                          "--runs-dir", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    steps = json.loads(sim.stdout)["first_run"]["tracking_steps"]
    run = next(line.split(": ", 1)[1] for line in sim.stderr.splitlines() if line.startswith("run folder: "))
    rev = subprocess.run([exe, "review", run, "--summary"], capture_output=True, text=True, timeout=120)
    assert rev.returncode == 0, rev.stderr
    line = next(l for l in rev.stdout.splitlines() if "tracking time" in l)
    assert int(line.split()[2]) == steps, (line, steps)


def test_review_cycle_prints_the_why(tmp_path):
    exe = os.environ["COMPANION_BIN"]
    recs = make_records()
    recs[7]["proposals"] = [{"mdp": "navigation", "state": "wp1", "action": "go_on", "actions": ["follow_trajectory"],
                             "value": 4.25, "iterations": 2, "inputs": {"P_nav": 0.875}}]
    run = tmp_path / "run"
    write_run(run, recs)
    out = subprocess.run([exe, "review", str(run), "--cycle", "7"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "go_on" in out.stdout and "value 4.250" in out.stdout and "P_nav = 0.875" in out.stdout
    assert not (run / "report.html").exists()
    bad = subprocess.run([exe, "review", str(run), "--cycle", "100000"], capture_output=True, text=True, timeout=60)
    assert bad.returncode != 0 and "cycle 100000 is not in this log" in bad.stderr


def test_export_csv_parses_back_one_row_per_record(tmp_path):
    import csv
    exe = os.environ["COMPANION_BIN"]
    recs = make_records()
    run = tmp_path / "run"
    write_run(run, recs)
    out = subprocess.run([exe, "export", str(run), "--format", "csv"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    with open(run / "export.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(recs)
    for row, rec in zip(rows, recs):
        assert int(row["cycle"]) == rec["cycle"]
        assert row["state"] == rec["state"]
        assert row["actions"] == ";".join(rec["actions"])
        assert float(row["probabilities.P_sys"]) == rec["probabilities"]["P_sys"]
        assert float(row["guarantee.margins.energy_j"]) == rec["guarantee"]["margins"]["energy_j"]
    mc = subprocess.run([exe, "export", str(run), "--format", "mcap"], capture_output=True, text=True, timeout=60)
    assert mc.returncode == 0, mc.stderr
    assert (run / "export.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_review_summary_strips_escape_sequences_from_the_log(tmp_path):
    exe = os.environ["COMPANION_BIN"]
    recs = make_records()
    recs[3]["link_events"] = ["STATUSTEXT: \x1b]0;owned\x07\x1b[2J\x1b[31mPreArm: Compass\x1b[0m not calibrated\r"]
    recs[4]["state"] = "wp1\x1b[1A"
    run = tmp_path / "run"
    write_run(run, recs)
    with open(run / "decisions.jsonl", "a") as f:
        f.write("not json \x1b[5m\n")
    out = subprocess.run([exe, "review", str(run), "--summary"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    for stream in (out.stdout, out.stderr):
        assert not any(ord(c) < 32 and c != "\n" or 0x7f <= ord(c) < 0xa0 for c in stream), repr(stream)
    assert "PreArm: Compass" in out.stdout  # the text itself is kept
