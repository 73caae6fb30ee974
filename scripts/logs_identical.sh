#!/usr/bin/env bash
# Behaviour-identity check between two git revisions: the decision logs and `--json` output of
# `companion simulate` for every scenario x policy x model must match byte for byte.
#
# Usage: scripts/logs_identical.sh [BASE_REV] [NEW_REV]
#   BASE_REV  default $BASE_REV, else 4e6a5f6 (main before the crates-by-role restructure)
#   NEW_REV   default: the working tree (uncommitted changes included)
# Env: PROFILE=debug|release (default debug: the cheapest build end to end; simulate is fast in
#      debug), JOBS (parallel cases, default 2), KEEP=1 keeps the run folders, CASES=REGEX keeps
#      only the cases whose name "scenario/policy/model" matches.
#
# Each revision other than the working tree is checked out in a detached `git worktree` under
# target/logs-identical/<side>/ and built there with its own CARGO_TARGET_DIR
# (target/logs-identical/<side>-target, kept between runs so rebuilds are incremental); the
# working tree builds in its normal target/. Every case runs with that revision's own params dir,
# the default seed and steps, and its own --runs-dir.
#
# What must match, per case:
#   - the set of files in the run folder (decisions.jsonl, decisions.N.jsonl, ...);
#   - every line of every decision-log part byte for byte, except on header lines
#     (`"kind":"header"`), which are compared with exactly these fields cut out, since they carry
#     the wall clock, the build's git revision or the command line (binary and folder paths):
#       started_utc, git_revision, command
#     (the header's `params` map, holding every params file's contents, is compared byte for byte);
#   - the `--json` stdout byte for byte, and the exit status.
#   Paths inside each side's source tree (the header's plan.route_file and zones_file) are compared
#   relative to it (each side's checkout is elsewhere).
# Logs of an older schema: when the base writes a lower header `schema` than the new side (schema 1
# sentences, schema 2 typed events), each base part is first rewritten by the new side's
# `companion-log-migrate` (companion-testkit: decision_log::migration, then the record written
# again from its typed value), so the records are compared after migration, byte for byte.
# The --json output of a migrated base is compared without its `decisions` (the log's records in
# the older schema; they are compared in the log). MIGRATE=0 compares the logs as written.
# PARAMS_MAY_DIFFER="mission.toml ..." names params files whose contents changed on purpose
# between the revisions (a new key the new loader reads, say): their entries in the header's
# `params` map are cut out too, and said so in the summary; every record is still compared
# byte for byte.
# Prints one line per case (`same`, or `DIFFERS` with the file and first differing line) and a
# summary; exits 0 only when every case matches.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
BASE_REV=${1:-${BASE_REV:-4e6a5f6}}
NEW_REV=${2:-${NEW_REV:-}}
PROFILE=${PROFILE:-debug}
JOBS=${JOBS:-2}
CASES=${CASES:-}
PARAMS_MAY_DIFFER=${PARAMS_MAY_DIFFER:-}
HEADER_VOLATILE_FIELDS="started_utc git_revision command $PARAMS_MAY_DIFFER"
MODELS="bfm reference monolithic"
WORK=$ROOT/target/logs-identical
mkdir -p "$WORK"
t_start=$(date +%s)

# log, checkout
. "$ROOT/scripts/lib/revisions.sh"

# Build the companion binary in source dir $1 with target dir $2; print the executable's path.
# Asks cargo for the path (--message-format=json) so a moved crate or target dir is followed.
build_companion() {
  local src=$1 tdir=$2 flags=() out
  [ "$PROFILE" = release ] && flags+=(--release)
  for sel in "-p companion --bin companion" "--workspace --bin companion"; do
    # shellcheck disable=SC2086
    if out=$(cd "$src" && CARGO_TARGET_DIR=$tdir cargo build -q "${flags[@]}" $sel \
        --message-format=json-render-diagnostics 2>"$WORK/build.err"); then
      printf '%s\n' "$out" | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "companion" \
            and m.get("executable"):
        print(m["executable"])
        break
'
      return 0
    fi
  done
  cat "$WORK/build.err" >&2
  return 1
}

# Prepare one side: source dir, binary and params dir, written to $WORK/<side>.env.
prepare() {
  local side=$1 rev=$2 src tdir desc bin
  resolve_side "$side" "$rev"
  log "building $side: $desc ($PROFILE) ..."
  bin=$(build_companion "$src" "$tdir")
  [ -x "$bin" ] || { log "no companion executable for $side"; exit 2; }
  # Copy the binary out: a later build in the same target dir must not change it mid-run.
  cp "$bin" "$WORK/$side-companion"
  printf 'SRC=%q\nDESC=%q\n' "$src" "$desc" >"$WORK/$side.env"
}

t_build=$(date +%s)
prepare base "$BASE_REV"
if [ -n "$NEW_REV" ]; then prepare new "$NEW_REV"; else prepare new ""; fi
# shellcheck disable=SC1090
BASE_SRC=$(. "$WORK/base.env"; echo "$SRC"); BASE_DESC=$(. "$WORK/base.env"; echo "$DESC")
NEW_SRC=$(. "$WORK/new.env"; echo "$SRC"); NEW_DESC=$(. "$WORK/new.env"; echo "$DESC")
# The new side's migration tool (always from the working tree's sources: it is the reader).
MIGRATE=${MIGRATE:-1}
if [ "$MIGRATE" = 1 ]; then
  log "building companion-log-migrate ..."
  (cd "$ROOT" && cargo build -q -p companion-testkit --bin companion-log-migrate)
  cp "$ROOT/target/debug/companion-log-migrate" "$WORK/companion-log-migrate"
fi
export MIGRATE
t_built=$(date +%s)

# Policies: the [priority] keys of the base's params/policies.toml (the new side must accept the
# same names, or its runs fail and the case differs).
POLICIES=$(python3 - "$BASE_SRC/params/policies.toml" <<'EOF'
import sys, tomllib
with open(sys.argv[1], "rb") as f:
    print(" ".join(tomllib.load(f)["priority"].keys()))
EOF
)
SCENARIOS=$(cd "$BASE_SRC/params/scenarios" && ls -1 *.toml | sed 's/\.toml$//')
NEW_SCENARIOS=$(cd "$NEW_SRC/params/scenarios" && ls -1 *.toml | sed 's/\.toml$//')
if [ "$SCENARIOS" != "$NEW_SCENARIOS" ]; then
  log "note: the scenario lists differ; running the union (a scenario missing on one side fails there)"
  SCENARIOS=$(printf '%s\n%s\n' "$SCENARIOS" "$NEW_SCENARIOS" | sort -u)
fi

RUN=$(mktemp -d "$WORK/run.XXXXXX")
[ "${KEEP:-}" = 1 ] || trap 'rm -rf "$RUN"' EXIT
: >"$RUN/cases"
for s in $SCENARIOS; do
  for p in $POLICIES; do
    for m in $MODELS; do
      c="$s/$p/$m"
      if [ -z "$CASES" ] || [[ $c =~ $CASES ]]; then echo "$c" >>"$RUN/cases"; fi
    done
  done
done
n_cases=$(wc -l <"$RUN/cases")
log "base: $BASE_DESC"
log "new:  $NEW_DESC"
log "$n_cases cases ($(echo $SCENARIOS | wc -w) scenarios x policies [$POLICIES] x models [$MODELS]), $JOBS at a time"

# One case on one side: run folder under $RUN/<side>/<case>/runs, stdout, stderr, exit status.
run_side() {
  local side=$1 case=$2 src=$3 s p m dir
  IFS=/ read -r s p m <<<"$case"
  dir=$RUN/$side/$s.$p.$m
  mkdir -p "$dir/runs"
  local rc=0
  (cd "$dir" && "$WORK/$side-companion" simulate --scenario "$s" --policy "$p" --model "$m" \
      --json --params "$src/params" --runs-dir "$dir/runs" >"$dir/stdout.json" 2>"$dir/stderr.txt") \
      || rc=$?
  echo "$rc" >"$dir/exit"
  # The base's parts at the new schema, when they are older (their header says so).
  if [ "$side" = base ] && [ "$MIGRATE" = 1 ]; then
    local part
    for part in "$dir"/runs/*/decisions*.jsonl; do
      [ -f "$part" ] || continue
      if head -c 200 "$part" | grep -q '"schema":1[,}]'; then
        "$WORK/companion-log-migrate" "$part" "$part.migrated" && mv "$part.migrated" "$part"
        : >"$dir/migrated"
      fi
    done
  fi
}

# Compare one case's two sides; print "same" or "DIFFERS <where>" on one line.
compare_case() {
  local case=$1 s p m
  IFS=/ read -r s p m <<<"$case"
  python3 - "$RUN/base/$s.$p.$m" "$RUN/new/$s.$p.$m" "$case" "$HEADER_VOLATILE_FIELDS" <<'EOF'
import json, os, re, sys

base, new, case, volatile = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4].split()

def field_re(name):
    # A top-level JSON string field; a header's other values hold no unescaped quote, so this
    # cannot match inside the params contents.
    return re.compile(rb',?"' + re.escape(name.encode()) + rb'":"(?:[^"\\]|\\.)*"')

def strip_header(line, where):
    obj = json.loads(line)
    params = obj.get("params") if isinstance(obj.get("params"), dict) else {}
    for name in volatile:
        if name not in obj and name not in params:
            continue
        line, n = field_re(name).subn(b"", line, count=1)
        if n != 1:
            raise SystemExit(f"DIFFERS {where}: header field {name} not cut out cleanly")
    return line

def is_header(line):
    return b'"kind":"header"' in line[:80]

def header_keys_differing(x, y):
    # Which top-level header fields differ (for the message only; the verdict is bytewise).
    try:
        ox, oy = json.loads(x), json.loads(y)
    except ValueError:
        return "?"
    keys = [k for k in dict.fromkeys(list(ox) + list(oy))
            if k not in volatile and ox.get(k) != oy.get(k)]
    if "params" in keys and isinstance(ox.get("params"), dict) and isinstance(oy.get("params"), dict):
        px, py = ox["params"], oy["params"]
        files = [f for f in sorted(set(px) | set(py)) if px.get(f) != py.get(f)]
        keys[keys.index("params")] = "params[" + ",".join(files) + "]"
    return ",".join(keys) or "byte layout"

def first_diff(a, b, label):
    """The first differing header line and the first differing other line, as a message."""
    la, lb = a.split(b"\n"), b.split(b"\n")
    found = []
    header_seen = other_seen = False
    for i, (x, y) in enumerate(zip(la, lb), 1):
        if is_header(x) and is_header(y):
            if not header_seen and strip_header(x, f"{label}:{i}") != strip_header(y, f"{label}:{i}"):
                header_seen = True
                found.append(f"{label} line {i} (header: {header_keys_differing(x, y)})")
        elif not other_seen and x != y:
            other_seen = True
            col = next((j for j, (u, v) in enumerate(zip(x, y)) if u != v), min(len(x), len(y))) + 1
            found.append(f"{label} line {i} byte {col}")
        if other_seen:
            break
    if not other_seen and len(la) != len(lb):
        found.append(f"{label} line {min(len(la), len(lb)) + 1} (one side ends: {len(la)} vs {len(lb)} lines)")
    return "; ".join(found) or None

# Paths inside a side's source tree (the header's plan.route_file / zones_file, the --json's) are
# compared relative to it: each side's checkout is elsewhere.
SRC = {base: os.environ["BASE_SRC"].encode(), new: os.environ["NEW_SRC"].encode()}

def read(p, side=None):
    with open(p, "rb") as f:
        raw = f.read()
    return raw.replace(SRC[side], b"<source tree>") if side in SRC else raw

def run_folder(side):
    runs = os.path.join(side, "runs")
    sub = sorted(os.listdir(runs))
    return os.path.join(runs, sub[0]) if len(sub) == 1 else None, sub

diff = None
eb, en = read(os.path.join(base, "exit")).strip(), read(os.path.join(new, "exit")).strip()
(fb, sb), (fn, sn) = run_folder(base), run_folder(new)
if eb != en:
    diff = f"exit status {eb.decode()} vs {en.decode()}"
def json_out(side, cut):
    # A migrated base's --json still holds its records in the older schema (`decisions`, the
    # log's records, compared above after migration): cut out on both sides, the rest bytewise.
    raw = read(os.path.join(side, "stdout.json"), side)
    if not cut:
        return raw
    obj = json.loads(raw)
    obj.pop("decisions", None)
    return json.dumps(obj, sort_keys=True).encode()
migrated = os.path.exists(os.path.join(base, "migrated"))
if diff is None:
    diff = first_diff(json_out(base, migrated), json_out(new, migrated),
                      "--json stdout" + (" (without decisions: base migrated)" if migrated else ""))
if diff is None and len(sb) != len(sn):
    diff = f"run folders: {len(sb)} vs {len(sn)}"
elif fb is not None and fn is not None:
    lb, ln = sorted(os.listdir(fb)), sorted(os.listdir(fn))
    if lb != ln:
        diff = (diff + "; " if diff else "") + f"run folder files {lb} vs {ln}"
    else:
        for name in lb:
            d = first_diff(read(os.path.join(fb, name), base), read(os.path.join(fn, name), new), name)
            if d:
                diff = (diff + "; " if diff else "") + d
                break
if diff is None and eb != b"0":
    print(f"FAILED  {case}: both runs exit {eb.decode()} (their stderr.txt: KEEP=1)")
elif diff is None and (fb is None or not os.path.exists(os.path.join(fb, "decisions.jsonl"))
                       or os.path.getsize(os.path.join(base, "stdout.json")) == 0):
    # Nothing was compared: a run that writes no log or no JSON must not pass as "same".
    print(f"FAILED  {case}: no decision log or no --json output to compare")
elif diff is None:
    print(f"same    {case}")
else:
    print(f"DIFFERS {case}: {diff}")
EOF
}

export RUN WORK BASE_SRC NEW_SRC HEADER_VOLATILE_FIELDS
export -f run_side compare_case
one_case() {
  # One write per case: parallel jobs' lines must not interleave in the shared pipe.
  local out
  out=$(run_side base "$1" "$BASE_SRC"; run_side new "$1" "$NEW_SRC"; compare_case "$1")
  printf '%s\n' "$out"
}
export -f one_case
t_runs=$(date +%s)
xargs -P "$JOBS" -I{} bash -c 'one_case "$1"' _ {} <"$RUN/cases" | tee "$RUN/results"
t_end=$(date +%s)

n_same=$(grep -c '^same' "$RUN/results" || true)
n_diff=$((n_cases - n_same))
echo "summary: $n_same of $n_cases cases identical, $n_diff differ (base $BASE_DESC; new $NEW_DESC);" \
  "build $((t_built - t_build)) s, runs $((t_end - t_runs)) s, total $((t_end - t_start)) s"
[ -n "$PARAMS_MAY_DIFFER" ] && echo "header params entries not compared (PARAMS_MAY_DIFFER): $PARAMS_MAY_DIFFER"
[ "${KEEP:-}" = 1 ] && echo "run folders kept in $RUN"
[ "$n_diff" -eq 0 ] && [ "$n_cases" -gt 0 ]
