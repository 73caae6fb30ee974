#!/usr/bin/env bash
# The fleet calibration's sufficient statistics on Apache Spark (local mode), over the same Parquet
# files companion-fleet wrote, compared with DataFusion's (docs/fleet.md "Calibration"; outside the
# test command). pyspark comes from PyPI into its own venv (SPARK_VENV, default .venv-spark); Java 17.
#   scripts/fleet_spark.sh DATASET_DIR
set -euo pipefail
cd "$(dirname "$0")/.."
DIR=$(realpath "$1")
VENV=${SPARK_VENV:-.venv-spark}
FLEET=${FLEET_BIN:-${CARGO_TARGET_DIR:-$PWD/target}/debug/companion-fleet}
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet pyspark
fi
STATS=$(mktemp /tmp/fleet-stats.XXXXXX.json)
trap 'rm -f "$STATS"' EXIT
"$FLEET" calibrate "$DIR" --statistics >"$STATS"
"$VENV/bin/python" - "$DIR" "$STATS" <<'PY'
import json, sys
from pyspark.sql import SparkSession
from pyspark.sql.types import StructType, StructField, LongType, DoubleType
ds, stats = sys.argv[1], json.load(open(sys.argv[2]))
spark = (SparkSession.builder.master("local[2]").appName("fleet-statistics")
         .config("spark.ui.enabled", "false").getOrCreate())
spark.sparkContext.setLogLevel("ERROR")
spark.read.parquet(f"{ds}/*/*/*/samples*.parquet").createOrReplaceTempView("samples")
grid = [(k, float(v)) for k, v in enumerate(stats["grid"])]
spark.createDataFrame(grid, StructType([StructField("k", LongType()), StructField("v0", DoubleType())])) \
     .createOrReplaceTempView("grid")
q, df = stats["queries"], stats["statistics"]
bad = []
def close(name, a, b):
    ok = a == b or abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1e-300)
    if not ok:
        bad.append(f"{name}: spark {a!r} datafusion {b!r}")
t = spark.sql(q["totals"]).collect()[0].asDict()
for k in ("n_ground", "n_air", "yy", "sum_y", "shipped_sse", "v_min", "v_max"):
    close(k, float(t[k]), float(df[k]))
bins = [r["bin"] for r in spark.sql(q["bins"]).collect()]
if bins != df["bins"]:
    bad.append(f"bins: spark {bins} datafusion {df['bins']}")
n = 0
for r in spark.sql(q["normals"]).collect():
    ata, aty = df["normals"][r["k"]]
    for name, (i, j) in {"sa": (0, 1), "si": (0, 2), "sc": (0, 3), "aa": (1, 1), "ai": (1, 2), "ac": (1, 3),
                         "ii": (2, 2), "ic": (2, 3), "cc": (3, 3)}.items():
        close(f"normals[{r['k']}].{name}", r[name], ata[i][j])
    for name, i in {"ay": 1, "iy": 2, "cy": 3}.items():
        close(f"normals[{r['k']}].{name}", r[name], aty[i])
    n += 1
# The activity durations' sums (a GROUP BY over stretches).
spark.read.parquet(f"{ds}/*/*/*/stretches*.parquet").createOrReplaceTempView("stretches")
nd = 0
for r in spark.sql(q["durations"]).collect():
    want = stats["durations"].get(r["a"])
    if r["n"] == 0:
        continue
    if want is None:
        bad.append(f"durations: {r['a']} from spark only")
        continue
    close(f"durations[{r['a']}].n", float(r["n"]), float(want["n"]))
    close(f"durations[{r['a']}].sum_d", r["sum_d"], want["sum_d"])
    close(f"durations[{r['a']}].sum_dd", r["sum_dd"], want["sum_dd"])
    nd += 1
if nd != len(stats["durations"]):
    bad.append(f"durations: {nd} activities from spark, {len(stats['durations'])} from datafusion")
# The BN rows' counts (a GROUP BY over bn_trials).
spark.read.parquet(f"{ds}/*/*/*/bn_trials*.parquet").createOrReplaceTempView("bn_trials")
want_bn = {(r["node"], r["parents"], r["success_state"]): (r["successes"], r["trials"]) for r in stats["bn_rows"]}
got_bn = {(r["node"], r["parents"], r["success_state"]): (r["successes"], r["trials"])
          for r in spark.sql(q["bn_rows"]).collect()}
if got_bn != want_bn:
    bad.append(f"bn_rows: spark {sorted(got_bn.items())[:5]}... datafusion {sorted(want_bn.items())[:5]}...")
# The legs' and vertical rates' sums (each query with the previous pass's results as literals).
spark.read.parquet(f"{ds}/*/*/*/legs*.parquet").createOrReplaceTempView("legs")
nl = 0
for name, entry in stats["legs"].items():
    got = spark.sql(entry["query"]).collect()[0].asDict()
    for col, want in entry["sums"].items():
        g = got.get(col)
        if g is None or want is None:
            if (g is None) != (want is None):
                bad.append(f"legs.{name}.{col}: spark {g!r} datafusion {want!r}")
            continue
        close(f"legs.{name}.{col}", float(g), float(want))
    nl += 1
legs_n = int(stats["legs"]["legs_sums"]["sums"]["n"] or 0)
print(f"spark {spark.version}: {int(t['n_air'])} airborne and {int(t['n_ground'])} ground samples, "
      f"{len(bins)} speed bins, normal equations at {n} candidate v0, durations of {nd} activities, "
      f"{len(got_bn)} BN rows, {nl} legs/rates queries over {legs_n} legs")
print(f"  sum_y {t['sum_y']!r} (datafusion {df['sum_y']!r}); yy {t['yy']!r} (datafusion {df['yy']!r})")
if bad:
    print("DIFFER:\n  " + "\n  ".join(bad[:20]))
    sys.exit(1)
print("the same sufficient statistics as DataFusion (1e-9 relative)")
PY
