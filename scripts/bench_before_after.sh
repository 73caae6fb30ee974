#!/usr/bin/env bash
# Before/after speed check between two git revisions, in one run on the same machine state.
#
# Usage: scripts/bench_before_after.sh [--quick] [--rounds N] [--criterion LIST] [BASE_REV] [NEW_REV]
#   BASE_REV  default $BASE_REV, else 4e6a5f6 (main before the crates-by-role restructure); any
#             revision from b5c24f9 on (one `companion` crate with nested engine crates) works:
#             targets are found by name, models under any benches/models/ dir
#   NEW_REV   default: the working tree (uncommitted changes included)
#   --rounds N        alternating rounds (default 6; --quick: 2 rounds and smaller budgets)
#   --criterion LIST  criterion benches to run besides the examples, comma-separated bench target
#                     names (default health,ingest; `none` for none; all of them:
#                     cycle,health,ingest,solve,schedule)
#   --same-models     both sides' bench_solve solve NEW's exported MDP models (the JSON format is
#                     the same since b5c24f9): when the models changed between the revisions,
#                     solve/* then compares the code alone (default: each side its own models)
#
# What runs: the release timing examples bench/compare uses, `bench_cycle` (the decision cycle:
# steady, changing, worst, monolithic), `bench_solve` (every paper model exported under
# */benches/models/, finite horizon / value iteration / policy iteration) and `bench_bn` (warm
# exact inference per health manager, on each side's own `export_health_bn` export), plus the
# criterion benches named by --criterion (short warm-up and measurement). `bench_ingest` needs
# bench/compare's pymavlink capture, so the MAVLink ingest is measured by the criterion `ingest`
# bench instead (it makes its capture in Rust).
#
# How: each revision other than the working tree is checked out in a detached `git worktree`
# under target/bench-before-after/<side>-<sha>/ and built there with its own CARGO_TARGET_DIR
# (target/bench-before-after/<side>-<sha>-target, kept so rebuilds are incremental); the working tree
# builds in its normal target/. Targets are found by name across the workspace
# (`cargo build --release --workspace --example NAME --bench NAME`), so crates may move between
# revisions. Every program runs with its revision's own source dir as working directory and
# COMPANION_PARAMS set to its own params/. Each round runs every program on both sides back to
# back, the side going first alternating between rounds (A B, B A, A B, ...), so slow drift of
# the machine's speed hits both sides alike. Per case and round a program reports one median;
# printed are the best (lowest) round of each side and their ratio after/before (other load on
# a shared machine only adds time), the median of the per-round ratios, and their range (the
# noise: a ratio inside the range an identical-code run shows is no evidence of a change).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
ROUNDS=6
QUICK=0
SAME_MODELS=0
CRITERION=health,ingest
POS=()
while [ $# -gt 0 ]; do
  case $1 in
    --quick) QUICK=1; ROUNDS=2 ;;
    --rounds) ROUNDS=$2; shift ;;
    --criterion) CRITERION=$2; shift ;;
    --same-models) SAME_MODELS=1 ;;
    -h|--help) sed -n '2,36p' "$0"; exit 0 ;;
    -*) echo "unknown option $1" >&2; exit 2 ;;
    *) POS+=("$1") ;;
  esac
  shift
done
BASE_REV=${POS[0]:-${BASE_REV:-4e6a5f6}}
NEW_REV=${POS[1]:-${NEW_REV:-}}
[ "$CRITERION" = none ] && CRITERION=
WORK=$ROOT/target/bench-before-after
mkdir -p "$WORK"
t_start=$(date +%s)
# log, checkout
. "$ROOT/scripts/lib/revisions.sh"

EXAMPLES=(bench_cycle bench_solve bench_bn export_health_bn)
# Build every program of one side; write "<target name> <executable>" lines to $WORK/<side>.exes.
build_side() {
  local side=$1 rev=$2 src tdir desc args=() key=$1
  # One checkout and target dir per revision, so comparing against another base and back
  # rebuilds nothing.
  [ -n "$rev" ] && key=$side-$(git rev-parse --short=10 "$rev^{commit}")
  resolve_side "$key" "$rev"
  for e in "${EXAMPLES[@]}"; do args+=(--example "$e"); done
  for b in ${CRITERION//,/ }; do args+=(--bench "$b"); done
  log "building $side: $desc (release) ..."
  (cd "$src" && CARGO_TARGET_DIR=$tdir cargo build -q --release --workspace "${args[@]}" \
      --message-format=json-render-diagnostics) >"$WORK/$side.build.json"
  mkdir -p "$WORK/$side-bin"
  python3 - "$WORK/$side.build.json" "$WORK/$side-bin" >"$WORK/$side.exes" <<'EOF'
import json, shutil, sys, os
seen = {}
for line in open(sys.argv[1]):
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable"):
        kind = m["target"]["kind"][0]
        if kind in ("example", "bench"):
            name = m["target"]["name"]
            # Copied out: a later build in the same target dir must not change it mid-run.
            dst = os.path.join(sys.argv[2], f"{kind}-{name}")
            shutil.copy2(m["executable"], dst)
            seen[f"{kind}:{name}"] = dst
for k, v in sorted(seen.items()):
    print(k, v)
EOF
  printf 'SRC=%q\nDESC=%q\n' "$src" "$desc" >"$WORK/$side.env"
}

build_side base "$BASE_REV"
build_side new "$NEW_REV"
t_built=$(date +%s)
log "built in $((t_built - t_start)) s; running $ROUNDS rounds ..."

python3 - "$WORK" "$ROUNDS" "$QUICK" "$CRITERION" "$SAME_MODELS" <<'EOF'
import glob, json, os, re, shlex, statistics, subprocess, sys, tempfile, time

work, rounds, quick, criterion = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1", sys.argv[4]
same_models = sys.argv[5] == "1"
criterion = [c for c in criterion.split(",") if c]

def side_env(side):
    env = {}
    for line in open(os.path.join(work, f"{side}.env")):
        k, v = line.rstrip("\n").split("=", 1)
        env[k] = shlex.split(v)[0] if v else ""
    exes = dict(line.split(" ", 1) for line in open(os.path.join(work, f"{side}.exes")).read().splitlines())
    return env["SRC"], env["DESC"], exes

sides = {}
tmp = tempfile.mkdtemp(prefix="run.", dir=work)
for side in ("base", "new"):
    src, desc, exes = side_env(side)
    d = os.path.join(tmp, side)
    os.makedirs(d)
    env = dict(os.environ, COMPANION_PARAMS=os.path.join(src, "params"),
               CRITERION_HOME=os.path.join(d, "criterion"))
    sides[side] = {"src": src, "desc": desc, "exes": exes, "dir": d, "env": env}

def run(side, args):
    s = sides[side]
    r = subprocess.run(args, cwd=s["src"], env=s["env"], capture_output=True, text=True)
    if r.returncode != 0:
        sys.stderr.write(r.stderr[-3000:])
        raise SystemExit(f"{side}: failed: {' '.join(args)}")
    return r.stdout

def exe(side, key):
    e = sides[side]["exes"].get(key)
    if e is None:
        raise SystemExit(f"{side}: no {key} built (is the target name unique in the workspace?)")
    return e

# Inputs, made per side from its own sources (they should be byte-identical; a warning if not).
def exported_models(src):
    """Every `benches/models/*.json` of the revision at any depth (`mdp_engine/benches/models`
    since the crate split, `companion/mdp_engine/benches/models` before it), build output and
    checkouts of other revisions (target/) left out."""
    found = []
    for d, subdirs, files in os.walk(src):
        subdirs[:] = [x for x in subdirs if x not in ("target", ".git", ".venv", "node_modules")]
        if d.endswith(os.path.join("benches", "models")):
            found += [os.path.join(d, f) for f in files if f.endswith(".json")]
    return sorted(found, key=os.path.basename)

for side, s in sides.items():
    models = exported_models(sides["new"]["src"] if same_models else s["src"])
    if not models:
        raise SystemExit(f"{side}: no exported MDP models (benches/models/*.json) in {s['src']}")
    budget = 0.05 if quick else 0.15
    s["plan"] = os.path.join(s["dir"], "plan.json")
    with open(s["plan"], "w") as f:
        json.dump({"cases": [
            {"name": f"{os.path.basename(p)[:-5]}/{solver}", "path": p, "solver": solver, "horizon": 100,
             "gamma": 0.95, "tolerance": 1e-10, "reps": 10000, "budget_s": budget}
            for p in models for solver in ("fh", "vi", "pi")]}, f)
    s["bn"] = os.path.join(s["dir"], "health_bn.json")
    run(side, [exe(side, "example:export_health_bn"), s["env"]["COMPANION_PARAMS"], s["bn"], "20"])
    s["models"] = {os.path.basename(p): open(p, "rb").read() for p in models}
if same_models:
    own = {os.path.basename(p): open(p, "rb").read() for p in exported_models(sides["base"]["src"])}
    if own != sides["base"]["models"]:
        print("note: --same-models: the base solves the new revision's MDP models, not its own", file=sys.stderr)
elif sides["base"]["models"] != sides["new"]["models"]:
    print("warning: the exported MDP models differ between the revisions (--same-models compares the "
          "solvers on one set)", file=sys.stderr)
def bn_export(path):
    # The export names each manager's params file by its absolute path: not part of the model.
    d = json.load(open(path))
    for m in d.get("managers", []):
        m.pop("file", None)
    return d
if bn_export(sides["base"]["bn"]) != bn_export(sides["new"]["bn"]):
    print("warning: the health BN exports differ between the revisions", file=sys.stderr)

def med_ns(ts):
    return statistics.median(ts)

UNIT_NS = {"ps": 1e-3, "ns": 1.0, "µs": 1e3, "us": 1e3, "ms": 1e6, "s": 1e9}

def parse_criterion(text):
    """Criterion's `<id>  time: [low estimate high]` lines (the id may sit on the line above)."""
    out, last = {}, None
    for line in text.splitlines():
        m = re.match(r"^(\S.*?)\s+time:\s+\[(.*)\]", line)
        if m:
            last, vals = m.group(1).strip(), m.group(2)
        else:
            m = re.match(r"^\s+time:\s+\[(.*)\]", line)
            if not m:
                if line and not line[0].isspace() and not line.startswith(("Benchmarking", "Found", "Gnuplot", "Warning")):
                    last = line.strip()
                continue
            vals = m.group(1)
        parts = vals.split()
        if "%" in vals or len(parts) != 6:
            continue  # a `change:` line (relative to the previous round), not a time
        est, unit = float(parts[2]), parts[3]
        out[last] = est * UNIT_NS[unit]
    return out

def program_runs(side):
    """(program, [(case, ns)]) for each program, in order."""
    s = sides[side]
    yield "bench_cycle", lambda: [
        (f"cycle/{c['name']}", c["median_us"] * 1e3)
        for c in json.loads(run(side, [exe(side, "example:bench_cycle"), "1000" if quick else "3000"]))["cases"]]
    yield "bench_solve", lambda: [
        (f"solve/{c['name']}", med_ns(c["times_ns"]))
        for c in json.loads(run(side, [exe(side, "example:bench_solve"), s["plan"]]))["cases"]]
    yield "bench_bn", lambda: [
        (f"bn/{m['name']}", med_ns(m["times_ns"]))
        for m in json.loads(run(side, [exe(side, "example:bench_bn"), s["bn"], "100000",
                                       "0.1" if quick else "0.3"]))["managers"]]
    for b in criterion:
        warm, meas = ("0.3", "0.8") if quick else ("1", "3")
        yield f"criterion {b}", lambda b=b, warm=warm, meas=meas: [
            (k if k.startswith(b + "/") else f"{b}/{k}", v) for k, v in parse_criterion(run(side, [
                exe(side, f"bench:{b}"), "--bench", "--warm-up-time", warm,
                "--measurement-time", meas, "--noplot"])).items()]

results = {}  # case -> side -> [ns per round]
order = []
t0 = time.time()
for r in range(rounds):
    pair = ("base", "new") if r % 2 == 0 else ("new", "base")
    progs = {side: list(program_runs(side)) for side in pair}
    for i in range(len(progs["base"])):
        for side in pair:
            name, fn = progs[side][i]
            for case, ns in fn():
                if case not in results:
                    results[case] = {"base": [], "new": []}
                    order.append(case)
                results[case][side].append(ns)
    print(f"round {r + 1}/{rounds} done ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)

def fmt(ns):
    for unit, f in (("s", 1e9), ("ms", 1e6), ("us", 1e3)):
        if ns >= f:
            return f"{ns / f:8.3f} {unit}"
    return f"{ns:8.1f} ns"

print(f"before: {sides['base']['desc']}")
print(f"after:  {sides['new']['desc']}")
print(f"{rounds} rounds, sides alternating. before/after: the best (lowest) per-round median of"
      " each side; ratio = after/before of those (other programs on the machine only ever add"
      " time, so the best round is the least disturbed); median: the median of the per-round"
      " ratios; range: the lowest and highest per-round ratio")
print(f"{'case':48s} {'before':>11s} {'after':>11s} {'ratio':>6s} {'median':>6s}  range")
ratios = []
for case in order:
    b, n = results[case]["base"], results[case]["new"]
    if len(b) != rounds or len(n) != rounds:
        print(f"{case:48s} missing on one side ({len(b)} vs {len(n)} rounds)")
        continue
    mb, mn = min(b), min(n)
    per = sorted(y / x for x, y in zip(b, n))
    ratios.append(mn / mb)
    print(f"{case:48s} {fmt(mb)} {fmt(mn)} {mn / mb:6.3f} {statistics.median(per):6.3f}"
          f"  [{per[0]:.3f} .. {per[-1]:.3f}]")
import shutil
shutil.rmtree(tmp, ignore_errors=True)
if ratios:
    gm = statistics.geometric_mean(ratios)
    print(f"summary: {len(ratios)} cases, geometric mean ratio {gm:.3f}, min {min(ratios):.3f},"
          f" max {max(ratios):.3f} (above 1 = after is slower)")
EOF
t_end=$(date +%s)
echo "total $((t_end - t_start)) s (build $((t_built - t_start)) s)"
