#!/usr/bin/env bash
# Write the seed corpus (real telemetry streams, the real params files) into fuzz/corpus/.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test -p companion-testkit --test fuzz_corpus -- --ignored write_seed_corpus
