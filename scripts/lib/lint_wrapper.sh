#!/usr/bin/env bash
# RUSTC_WORKSPACE_WRAPPER for scripts/test.sh: the shipped code of the workspace's crates is linted
# for clippy::too_many_lines (clippy.toml's threshold) by clippy-driver while it is compiled for the
# tests, instead of by a separate `cargo clippy`, whose check-mode build compiled every dependency a
# second time (DataFusion's alone took ~6 min of CI). clippy-driver is rustc plus lint passes: the
# code it generates is rustc's.
#
# Linted: a crate root under src/ compiled without --test (libraries, binaries), of every member
# but companion-testkit (test support). Not linted: tests, unit-test builds (--test), examples,
# benches, build scripts, version queries. Cargo calls this as `lint_wrapper.sh RUSTC ARGS...`.
# bash, not sh: dash drops environment names it cannot hold, such as CARGO_BIN_EXE_companion-fleet.
lint=0
if [ "$CARGO_PKG_NAME" != companion-testkit ]; then
  for a in "$@"; do
    case "$a" in
      --test) lint=0; break ;;
      src/*.rs | */src/*.rs) lint=1 ;;
    esac
  done
fi
if [ "$lint" = 1 ]; then
  # cargo-clippy's way of handing lint flags to the driver (separated by __CLIPPY_HACKERY__).
  CLIPPY_ARGS="-A__CLIPPY_HACKERY__clippy::all__CLIPPY_HACKERY__-D__CLIPPY_HACKERY__clippy::too_many_lines__CLIPPY_HACKERY__"
  export CLIPPY_ARGS
  exec clippy-driver "$@"
fi
exec "$@"
