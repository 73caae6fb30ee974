"""companion-fleet (issue 38, docs/fleet.md): 50 simulated runs and 3 stand-in flights ingested into a
Parquet dataset; the report's figures equal those computed here from the JSON lines (plain json, not the
code under test); pyarrow and DuckDB read the files with the documented schema; ingest is idempotent and a
run killed mid-ingest (SIGKILL at random points) leaves a dataset that reads and reports right."""
from __future__ import annotations

import hashlib
import json
import os
import random
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path
from typing import Any, Dict, List, Tuple

import duckdb
import pyarrow.parquet as pq
import pytest

from helpers import companion_fly_cmd
from standin.config import StandinConfig
from standin_autopilot import StandinAutopilot

ROOT = Path(__file__).resolve().parent.parent
TABLES = ["runs", "records", "proposals", "events", "commands", "telemetry", "samples", "legs", "bn_trials",
          "stretches"]
SCENARIOS = ["complete-1", "energy-drift", "vibrations", "nominal", "lidar-failure"]
FAILURE_WORDS = {"DENIED", "UNSUPPORTED", "TEMPORARILY_REJECTED", "NOT_READY", "TIMEOUT", "FAILED"}


def fleet_bin() -> str:
    return os.path.join(os.path.dirname(os.environ["COMPANION_BIN"]), "companion-fleet")


def fleet(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    out = subprocess.run([fleet_bin(), *args], capture_output=True, text=True, timeout=600)
    if check:
        assert out.returncode == 0, f"companion-fleet {' '.join(args)}\n{out.stdout[-2000:]}\n{out.stderr[-3000:]}"
    return out


# ------------------------------------------------------------------------------------------------
# The runs: written once per module
# ------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Dict[str, Any]:
    base = tmp_path_factory.mktemp("fleet-runs")
    sim = base / "sim"
    exe = os.environ["COMPANION_BIN"]
    for k in range(50):
        cmd = [exe, "simulate", "--steps", "25", "--seed", str(k + 1), "--scenario", SCENARIOS[k % len(SCENARIOS)],
               "--runs-dir", str(sim)]
        if k % 3 == 0:
            cmd += ["--mission", "tracking"]       # the typed plan: a second route in the report
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr[-2000:]
    flights = base / "flights"
    for k in range(3):
        sa = StandinAutopilot(StandinConfig(listen="tcp:127.0.0.1:0", speedup=4.0, ekf_ready_s=2.0, seed=k + 1)).start()
        try:
            cmd = companion_fly_cmd(exe, sa.url, flights, extra=["--duration", "5s"])
            out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
            assert out.returncode == 0, out.stderr[-2000:]
        finally:
            sa.stop()
    crafted = base / "crafted"
    write_crafted_run(crafted / "run1", schema=1)
    write_crafted_run(crafted / "run2", schema=2)
    sim_runs = sorted(p for p in sim.iterdir() if (p / "decisions.jsonl").is_file())
    flight_runs = sorted(p for p in flights.iterdir() if (p / "decisions.jsonl").is_file())
    assert len(sim_runs) == 50 and len(flight_runs) == 3, (sim_runs, flight_runs)
    assert all((p / "flight.tlog").is_file() for p in flight_runs)
    return {"base": base, "sim": sim, "flights": flights, "crafted": crafted,
            "vehicle_of": {**{p: "sim" for p in sim_runs}, **{p: "standin" for p in flight_runs},
                           crafted / "run1": "crafted", crafted / "run2": "crafted"}}


# The crafted run's events and command results: as record schema 1 wrote them (sentences; an old log, read
# through the companion's migration) and as schema 2 writes them (objects tagged by kind, with their text).
# The gate's refusal is an `operator` event of kind `start_refused` (`by`, `why`); a free-text event shaped like
# one (a scenario's hazard can say anything) is kind `other` and no refusal.
REFUSED = ("operator: start refused (MAV_CMD_MISSION_START from the ground station): needs 162 kJ, 150 available; "
           "still waiting for the operator")
LOOKALIKE = "operator: start refused (models): not the gate's; still waiting for the operator"
CRAFTED = {
    1: {"refused": REFUSED, "lookalike": LOOKALIKE, "lost": "link lost",
        "results": ["TIMEOUT (no answer)", "DENIED", "FAILED (Cancelled(\"x\"))", "ACCEPTED"]},
    2: {"refused": {"kind": "operator", "operator": {"kind": "start_refused", "by": "start_command",
                                                     "why": "needs 162 kJ, 150 available", "text": REFUSED},
                    "text": REFUSED},
        "lookalike": {"kind": "other", "text": LOOKALIKE}, "lost": {"kind": "lost", "text": "link lost"},
        "results": [{"kind": "TIMEOUT", "why": "no answer", "text": "TIMEOUT (no answer)"},
                    {"kind": "DENIED", "text": "DENIED"}, {"kind": "CANCELLED", "why": "x", "text": "CANCELLED (x)"},
                    {"kind": "ACCEPTED", "text": "ACCEPTED"}]},
}
# How a start came about (companion-core's StartBy), as a schema-1 sentence says it: the independent reading of
# an old log's refusal (docs/decision-log.md, `operator` events).
START_BY = {"--auto-start (no operator)": "auto_start",
            "the pilot armed the vehicle (--start-on-arm)": "pilot_armed",
            "MAV_CMD_MISSION_START from the ground station": "start_command",
            "the pilot switched the armed vehicle to GUIDED": "guided_switch"}


def refusal(e: Any, typed: bool):
    """(by, why) of a start the operator gate refused, else None: schema 2 by the event's kind and fields,
    schema 1 by the gate's sentence (`operator: start refused (<by>): <why>; still waiting for the operator`)."""
    if typed:
        op = e.get("operator") or {}
        return (op["by"], op["why"]) if e["kind"] == "operator" and op.get("kind") == "start_refused" else None
    m = re.fullmatch(r"operator: start refused \((.*?)\): (.*); still waiting for the operator", e)
    return (START_BY[m.group(1)], m.group(2)) if m and m.group(1) in START_BY else None


def write_crafted_run(d: Path, schema: int) -> None:
    """A run with what neither the simulated runs nor the short stand-in flights show: a refused start, a
    performance drift, failed and cancelled commands, a link loss (the report's every figure is then non-zero
    somewhere), written in the decision log's record `schema` 1 or 2."""
    d.mkdir(parents=True)
    said = CRAFTED[schema]
    lines = [{"schema": schema, "kind": "header", "started_utc": "2026-01-02T03:04:05Z", "git_revision": "crafted",
              "command": "companion fly --connect tcp:x", "params": {}, "part": 0,
              "plan": {"mission": "tracking", "route_file": "/somewhere/else/tracking_route.toml", "zones_file": None,
                       "activities": 3, "planned_energy_j": 1000.0,
                       "planned_duration_s": 100.0}}]
    for c in range(6):
        lines.append({
            "cycle": c, "time_s": 2.0 * c, "state": "base",
            "events": [said["refused"]] if c < 2 else [said["lookalike"]] if c == 2 else [],
            "link_events": [said["lost"]] if c == 3 else [],
            "commands": [{"action": "take_off", "command": "MAV_CMD_NAV_TAKEOFF", "result": r, "attempts": 1}
                         for r in (said["results"] if c == 4 else [])],
            "guarantee": {"activity": 0, "activity_name": "transit", "goals": {"energy_j": 2000.0, "duration_s": 200.0},
                          "margins": {"energy_j": 900.0 - c, "duration_s": 95.0 - c},
                          "power": {"predicted_w": 10.0, "activity_s": c, "predicted_j": 1.0, "drift": c >= 3,
                                    "drift_began": c == 3, "energy_scale": 1.0},
                          "reallocation": {"trigger": "margin", "reason": "x", "allocation": [], "margins_after": {}}
                          if c == 5 else None},
        })
    lines.append({"kind": "event", "cycle": 5, "time_s": 10.0, "event": "link lost"})
    (d / "decisions.jsonl").write_text("".join(json.dumps(o) + "\n" for o in lines))


def ingest_all(runs: Dict[str, Any], into: Path) -> None:
    fleet("ingest", str(runs["sim"]), "--into", str(into))
    fleet("ingest", str(runs["flights"]), "--into", str(into), "--vehicle", "standin")
    fleet("ingest", str(runs["crafted"]), "--into", str(into), "--vehicle", "crafted")


# ------------------------------------------------------------------------------------------------
# The independent figures: plain json over the JSON lines (docs/fleet.md "Report")
# ------------------------------------------------------------------------------------------------

def log_parts(run: Path) -> List[Path]:
    parts = [run / "decisions.jsonl"]
    k = 1
    while (run / f"decisions.{k}.jsonl").is_file():
        parts.append(run / f"decisions.{k}.jsonl")
        k += 1
    return parts


def content_id(run: Path) -> str:
    h = hashlib.sha256()
    files = log_parts(run) + ([run / "flight.tlog"] if (run / "flight.tlog").is_file() else [])
    for f in files:
        data = f.read_bytes()
        h.update(data)
        h.update(len(data).to_bytes(8, "little"))
    return "sha256:" + h.hexdigest()


def read_run(run: Path) -> Tuple[Dict[str, Any], List[Dict[str, Any]]]:
    header, records = {}, []
    for part in log_parts(run):
        for line in part.read_text().splitlines():
            if not line.strip():
                continue
            o = json.loads(line)
            if o.get("kind") == "header":
                header = header or o
            elif "kind" not in o:
                records.append(o)
    return header, records


def route_of(header: Dict[str, Any]) -> str:
    plan = header.get("plan") or {}
    if plan.get("route_file"):
        return re.split(r"[/\\]", plan["route_file"])[-1]
    for v in (plan.get("mission"), header.get("scenario")):
        if isinstance(v, str) and v:
            return v
    return "unknown"


def flown(records: List[Dict[str, Any]], goal: str):
    value = None
    for r in records:
        g = r.get("guarantee") or {}
        if goal in (g.get("goals") or {}) and goal in (g.get("margins") or {}):
            value = g["goals"][goal] - g["margins"][goal]
    return value


def mean(xs):
    xs = [x for x in xs if x is not None]
    return sum(xs) / len(xs) if xs else None


def expected(runs: Dict[str, Any], present: set) -> Dict[str, Any]:
    """The report's sections computed from the JSON lines of the runs whose content id is in `present`."""
    per_run = []
    refusals: Dict[tuple, int] = {}
    failures: Dict[tuple, int] = {}
    versions: Dict[tuple, int] = {}
    for run, vehicle in runs["vehicle_of"].items():
        if content_id(run) not in present:
            continue
        header, records = read_run(run)
        route = route_of(header)
        key = (vehicle, route)
        plan = header.get("plan") or {}
        row = {"key": key, "records": len(records), "version": header.get("git_revision"),
               "hours": max((r.get("time_s", 0.0) for r in records), default=0.0) / 3600.0,
               "planned_e": plan.get("planned_energy_j"), "planned_d": plan.get("planned_duration_s"),
               "flown_e": flown(records, "energy_j"), "flown_d": flown(records, "duration_s"),
               "refused": 0, "drift": 0, "realloc": 0, "fails": 0, "links": 0}
        typed = header.get("schema", 1) >= 2   # record schema 2: events and results tagged by kind
        for r in records:
            for e in r.get("events") or []:
                refused = refusal(e, typed)
                if refused:
                    row["refused"] += 1
                    refusals[(*key, *refused)] = refusals.get((*key, *refused), 0) + 1
            if (((r.get("guarantee") or {}).get("power") or {}).get("drift_began")):
                row["drift"] += 1
            if ((r.get("guarantee") or {}).get("reallocation") or {}).get("trigger") is not None:
                row["realloc"] += 1
            row["links"] += sum(1 for e in r.get("link_events") or []
                                if (e["kind"] == "lost" if typed else e == "link lost"))
            for c in r.get("commands") or []:
                res = c.get("result", "")
                word = res["kind"] if typed else res.split(" ", 1)[0]
                # schema 1: `FAILED (Cancelled(..))` was a cancel (the migration reads it as CANCELLED)
                if word in FAILURE_WORDS and not (not typed and res.startswith("FAILED (Cancelled(")):
                    row["fails"] += 1
                    k = (*key, c.get("command"), word)
                    failures[k] = failures.get(k, 0) + 1
        versions[(*key, row["version"])] = versions.get((*key, row["version"]), 0) + 1
        per_run.append(row)
    summary = []
    for key in sorted({r["key"] for r in per_run}):
        rs = [r for r in per_run if r["key"] == key]
        both_e = [r["flown_e"] - r["planned_e"] for r in rs if r["flown_e"] is not None and r["planned_e"] is not None]
        both_d = [r["flown_d"] - r["planned_d"] for r in rs if r["flown_d"] is not None and r["planned_d"] is not None]
        summary.append({
            "vehicle": key[0], "route": key[1], "flights": len(rs), "hours": sum(r["hours"] for r in rs),
            "records": sum(r["records"] for r in rs), "versions": len({r["version"] for r in rs}),
            "refused_starts": sum(r["refused"] for r in rs), "drift_events": sum(r["drift"] for r in rs),
            "reallocations": sum(r["realloc"] for r in rs),
            "command_failures": sum(r["fails"] for r in rs), "link_losses": sum(r["links"] for r in rs),
            "planned_energy_j": mean([r["planned_e"] for r in rs]), "flown_energy_j": mean([r["flown_e"] for r in rs]),
            "energy_error_j": mean(both_e),
            "planned_duration_s": mean([r["planned_d"] for r in rs]),
            "flown_duration_s": mean([r["flown_d"] for r in rs]), "duration_error_s": mean(both_d),
        })
    return {
        "summary": summary,
        "refused_starts": [{"vehicle": k[0], "route": k[1], "refused_by": k[2], "reason": k[3], "starts": n}
                           for k, n in sorted(refusals.items())],
        "command_failures": [{"vehicle": k[0], "route": k[1], "command": k[2], "kind": k[3], "failures": n}
                             for k, n in sorted(failures.items())],
        "versions": [{"vehicle": k[0], "route": k[1], "git_revision": k[2], "flights": n}
                     for k, n in sorted(versions.items())],
    }


def same(a: Any, b: Any) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return a == b or abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1.0)
    return a == b


def assert_report_matches(got: Dict[str, Any], want: Dict[str, Any]) -> None:
    assert set(got) == set(want), got.keys()
    for section, rows in want.items():
        g = got[section]
        assert len(g) == len(rows), (section, g, rows)
        for gr, wr in zip(g, rows):
            for col, v in wr.items():
                assert same(gr.get(col), v), (section, col, gr, wr)


def batch_dirs(dataset: Path) -> List[Path]:
    """The dataset's batch folders: one per ingest and partition (vehicle, date)."""
    return sorted(dataset.glob("vehicle=*/date=*/batch=*"))


def table_files(batch: Path, table: str) -> List[Path]:
    """A table's files in a batch folder: <table>.parquet, then <table>.<n>.parquet when a run's columns differ."""
    return sorted(p for p in batch.iterdir() if re.fullmatch(rf"{table}(\.\d+)?\.parquet", p.name))


def present_ids(dataset: Path) -> set:
    ids = set()
    for d in batch_dirs(dataset):
        for f in table_files(d, "runs"):
            ids.update(pq.ParquetFile(f).read(columns=["run_id"]).column("run_id").to_pylist())
    return ids


def report(dataset: Path) -> Dict[str, Any]:
    return json.loads(fleet("report", str(dataset), "--json").stdout)


# ------------------------------------------------------------------------------------------------
# Tests
# ------------------------------------------------------------------------------------------------

def test_report_figures_equal_the_json_lines(runs, tmp_path):
    ds = tmp_path / "fleet"
    ingest_all(runs, ds)
    ids = {content_id(r) for r in runs["vehicle_of"]}
    assert present_ids(ds) == ids and len(ids) == 55
    want = expected(runs, ids)
    # Every figure is non-zero somewhere: two routes of simulated runs, the flights', the crafted run's.
    assert len(want["summary"]) >= 4, want["summary"]
    for figure in ("drift_events", "reallocations", "refused_starts", "command_failures", "link_losses"):
        assert sum(r[figure] for r in want["summary"]) > 0, (figure, want["summary"])
    assert want["refused_starts"] and want["command_failures"], want
    assert_report_matches(report(ds), want)
    # run ids are the content hashes; each row of runs names its source folder
    rows = json.loads(fleet("sql", str(ds), "SELECT run_id, source FROM runs ORDER BY source", "--json").stdout)
    assert {r["run_id"] for r in rows} == ids
    # the HTML page holds the same sections
    page = tmp_path / "fleet.html"
    fleet("report", str(ds), "--html", str(page))
    html = page.read_text()
    for section in want:
        assert f"<h2>{section}</h2>" in html


def test_sql_answers_over_every_table(runs, tmp_path):
    ds = tmp_path / "fleet"
    ingest_all(runs, ds)
    n_records = sum(len(read_run(r)[1]) for r in runs["vehicle_of"])
    n_commands = sum(len(rec.get("commands") or []) for r in runs["vehicle_of"] for rec in read_run(r)[1])
    got = json.loads(fleet("sql", str(ds), "SELECT COUNT(*) AS n FROM records", "--json").stdout)
    assert got == [{"n": n_records}]
    got = json.loads(fleet("sql", str(ds), "SELECT COUNT(*) AS n FROM commands", "--json").stdout)
    assert got == [{"n": n_commands}]
    got = json.loads(fleet("sql", str(ds), "SELECT vehicle, COUNT(DISTINCT run_id) AS n FROM telemetry "
                           "GROUP BY vehicle", "--json").stdout)
    assert got == [{"vehicle": "standin", "n": 3}]
    # events and commands by their kinds (record schema 2), as the flights' JSON lines tag them
    want: Dict[tuple, int] = {}
    for run in sorted(runs["flights"].iterdir()):
        for rec in read_run(run)[1]:
            for source, field in (("record", "events"), ("link", "link_events")):
                for e in rec.get(field) or []:
                    want[(source, e["kind"])] = want.get((source, e["kind"]), 0) + 1
            for c in rec.get("commands") or []:
                want[("command", c["result"]["kind"])] = want.get(("command", c["result"]["kind"]), 0) + 1
    got = json.loads(fleet("sql", str(ds), "SELECT source, kind, COUNT(*) AS n FROM events WHERE vehicle = 'standin' "
                           "AND source <> 'log' GROUP BY 1, 2 UNION ALL SELECT 'command', kind, COUNT(*) FROM commands "
                           "WHERE vehicle = 'standin' GROUP BY 1, 2", "--json").stdout)
    assert {(r["source"], r["kind"]): r["n"] for r in got} == want
    assert ("record", "command") in want and ("link", "autopilot") in want, want
    out = fleet("sql", str(ds), "SELECT nope FROM records", check=False)
    assert out.returncode != 0 and "nope" in out.stderr and "panicked" not in out.stderr


def documented_schema() -> Dict[str, Dict[str, str]]:
    """Column -> type of each table, from docs/fleet.md's schema tables."""
    doc = (ROOT / "docs" / "fleet.md").read_text()
    out: Dict[str, Dict[str, str]] = {}
    for section in re.split(r"^### ", doc, flags=re.M)[1:]:
        m = re.match(r"(\w+) \(one row per", section)
        if not m:
            continue
        cols = {}
        for line in section.split("\n## ")[0].splitlines():
            if not line.startswith("| `"):
                continue
            cells = [c.strip() for c in line.strip("|").split("|")]
            for name in re.findall(r"`([a-z_0-9]+)`", cells[0]):
                cols[name] = cells[1]
        out[m.group(1)] = cols
    assert set(out) == set(TABLES), out.keys()
    return out


ARROW_TYPES = {"string": "string", "int64": "int64", "double": "double", "bool": "bool",
               "list<string>": "list<item: string>"}
DYNAMIC = ("obs_", "p_", "ev_", "margin_", "goal_", "drift_", "veh_")


def test_pyarrow_and_duckdb_read_the_documented_schema(runs, tmp_path):
    ds = tmp_path / "fleet"
    ingest_all(runs, ds)
    schema = documented_schema()
    assert len(present_ids(ds)) == 55
    # compacted: one folder per ingest and partition (vehicle, date), not one per run
    partitions = {(r["vehicle"], r["date"]) for d in batch_dirs(ds) for f in table_files(d, "runs")
                  for r in pq.ParquetFile(f).read(columns=["vehicle", "date"]).to_pylist()}
    assert len(batch_dirs(ds)) == len(partitions) < 55
    for d in batch_dirs(ds):
        for table, cols in schema.items():
            files = table_files(d, table)
            assert files, (d, table)
            for f in files:
                got = {fld.name: str(fld.type) for fld in pq.read_schema(f)}
                for name, typ in cols.items():
                    assert got.get(name) == ARROW_TYPES[typ], (f, name, got.get(name))
                extra = [c for c in got if c not in cols]
                assert table == "records" or not extra, (table, extra)
                assert all(c.startswith(DYNAMIC) for c in extra), extra
    con = duckdb.connect()
    glob = str(ds / "*" / "*" / "*")
    n = con.execute(f"SELECT COUNT(*) FROM read_parquet('{glob}/records*.parquet', union_by_name = true)").fetchone()[0]
    assert n == sum(len(read_run(r)[1]) for r in runs["vehicle_of"])
    per_vehicle = dict(con.execute(f"SELECT vehicle, COUNT(*) FROM read_parquet('{glob}/runs*.parquet') "
                                   "GROUP BY vehicle").fetchall())
    assert per_vehicle == {"sim": 50, "standin": 3, "crafted": 2}
    # one flight's telemetry: as many rows as the tlog has frames (counted here from the headers)
    flight = sorted(runs["flights"].iterdir())[0]
    data, i, frames = (flight / "flight.tlog").read_bytes(), 0, 0
    while i < len(data):
        stx, plen = data[i + 8], data[i + 9]
        i += 8 + (12 + plen + (13 if data[i + 10] & 1 else 0) if stx == 0xFD else 8 + plen)
        frames += 1
    rid = content_id(flight)
    t = con.execute(f"SELECT COUNT(*) FROM read_parquet('{glob}/telemetry*.parquet', union_by_name = true) WHERE run_id = ?", [rid])
    assert t.fetchone()[0] == frames > 0


def snapshot(ds: Path) -> Dict[str, Tuple[int, int]]:
    return {str(p.relative_to(ds)): (p.stat().st_size, p.stat().st_mtime_ns) for p in ds.rglob("*")}


def test_ingesting_twice_changes_nothing(runs, tmp_path):
    ds = tmp_path / "fleet"
    ingest_all(runs, ds)
    before = snapshot(ds)
    out = fleet("ingest", str(runs["sim"]), "--into", str(ds))
    assert "0 run(s) added, 50 already there" in out.stdout
    # a copy of a run under another name, and another vehicle id, is the same run
    copy = tmp_path / "copy"
    shutil.copytree(sorted(runs["flights"].iterdir())[0], copy)
    out = fleet("ingest", str(copy), "--into", str(ds), "--vehicle", "other")
    assert "0 run(s) added, 1 already there" in out.stdout
    assert snapshot(ds) == before


def test_sigkill_mid_ingest_leaves_a_dataset_that_reports_right(runs, tmp_path):
    ds = tmp_path / "fleet"
    all_ids = {content_id(r) for r in runs["vehicle_of"]}
    # How long a whole ingest of the simulated runs takes here, to kill within it.
    scratch = tmp_path / "scratch"
    t0 = time.monotonic()
    fleet("ingest", str(runs["sim"]), "--into", str(scratch))
    whole = time.monotonic() - t0
    rng = random.Random(38)
    kills = 0
    # 20 kills that land mid-ingest: a kill that comes after the ingest ended is not one, so under a loaded
    # machine's timing more attempts are made (bounded), each still checked.
    for k in range(60):
        if kills == 20:
            break
        src = runs["sim"] if k % 4 else runs["flights"]
        extra = [] if k % 4 else ["--vehicle", "standin"]
        proc = subprocess.Popen([fleet_bin(), "ingest", str(src), "--into", str(ds), *extra],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(rng.uniform(0.0, whole / 4))
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            kills += 1
        proc.wait(timeout=60)
        present = present_ids(ds)
        assert present <= all_ids
        for d in batch_dirs(ds):
            assert all(table_files(d, t) for t in TABLES), d
        if present:
            assert_report_matches(report(ds), expected(runs, present))
    assert kills == 20, f"only {kills} of {k + 1} ingests were killed mid-way"
    ingest_all(runs, ds)
    assert present_ids(ds) == all_ids
    assert not list(ds.glob(".tmp-*")), "the last ingest removes the killed ingests' temporary folders"
    assert_report_matches(report(ds), expected(runs, all_ids))


def test_an_old_log_exports_as_the_new(runs, tmp_path):
    """The crafted run as record schema 1 wrote it (sentences) exports, through the companion's log reader and
    its migration, the same events and commands rows, by kind, as the same run written in schema 2."""
    tables = {}
    for name in ("run1", "run2"):
        out = tmp_path / name
        fleet("export", str(runs["crafted"] / name), "--out", str(out), "--vehicle", "crafted")
        tables[name] = {t: [{k: v for k, v in row.items() if k != "run_id"}
                            for row in pq.read_table(out / f"{t}.parquet").to_pylist()]
                        for t in ("events", "commands")}
    assert tables["run1"] == tables["run2"]
    commands = tables["run1"]["commands"]
    assert [(c["kind"], c["text"], c["why"]) for c in commands] == [
        ("TIMEOUT", "TIMEOUT (no answer)", "no answer"), ("DENIED", "DENIED", None),
        ("CANCELLED", "CANCELLED (x)", "x"), ("ACCEPTED", "ACCEPTED", None)]
    events = tables["run1"]["events"]
    refused = ("record", "operator", REFUSED, "start_refused", "start_command", "needs 162 kJ, 150 available")
    assert [(e["source"], e["kind"], e["text"], e["operator"], e["start_by"], e["why"]) for e in events] == [
        refused, refused, ("record", "other", LOOKALIKE, None, None, None),
        ("link", "lost", "link lost", None, None, None), ("log", "other", "link lost", None, None, None)]


def test_export_writes_one_runs_tables(runs, tmp_path):
    run = sorted(runs["sim"].iterdir())[0]
    out = tmp_path / "one"
    fleet("export", str(run), "--out", str(out))
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{t}.parquet" for t in TABLES)
    records = pq.read_table(out / "records.parquet").to_pylist()
    _, want = read_run(run)
    assert [r["cycle"] for r in records] == [r.get("cycle", 0) for r in want]
    assert [r["state"] for r in records] == [r.get("state") for r in want]
    assert [r["actions"] for r in records] == [r.get("actions", []) for r in want]
    obs = sorted({k for r in want for k in r.get("observations", {})})
    for name in obs:
        assert [r[f"obs_{name}"] for r in records] == [r.get("observations", {}).get(name) for r in want], name
    # an unreadable run is refused with its name, not a panic
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "decisions.jsonl").write_text("")
    got = fleet("export", str(bad), "--out", str(tmp_path / "bad-out"), check=False)
    assert got.returncode != 0 and "bad" in got.stderr and "panicked" not in got.stderr
