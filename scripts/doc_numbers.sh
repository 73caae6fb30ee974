#!/usr/bin/env bash
# Every number docs/ quotes that the code produces (marked `<!-- doc-number NAME -->` after the
# number), recomputed and printed beside what the doc writes; exits non-zero when a doc is stale.
# The check itself is the test companion/tests/doc_numbers.rs (part of `cargo test`); this script
# runs it and shows its lines. Usage: scripts/doc_numbers.sh
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(cargo test -q -p companion --test doc_numbers -- --nocapture --test-threads 1 2>&1) && rc=0 || rc=$?
grep '^doc-number ' <<<"$out" || true
if [ "$rc" -ne 0 ]; then
    grep -v '^doc-number ' <<<"$out" >&2
    echo "doc_numbers: a doc is stale (see above)" >&2
fi
exit "$rc"
