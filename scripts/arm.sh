#!/usr/bin/env bash
# The companion on ARM: cross-builds the release binary for the SoCKit's Cortex-A9
# (armv7-unknown-linux-gnueabihf), runs the engine test suites and the binary under qemu-user, and
# reports the stripped binary's size. Installs what is missing first (Debian's cross gcc, the ARM
# C libraries, qemu-user; rustup's rust-std for the targets) and skips what is already there, so a
# second run is incremental. Linkers and qemu runners come from .cargo/config.toml.
#
#   scripts/arm.sh                     armv7 (the SoCKit)
#   scripts/arm.sh --aarch64           aarch64-unknown-linux-gnu only
#   scripts/arm.sh --armv7 --aarch64   both
#   scripts/arm.sh --install           install only (for the selected targets)
#   scripts/arm.sh --musl              static release binaries for older boards (armv7 and
#                                      aarch64 musl, linked by the toolchain's rust-lld; no C
#                                      cross toolchain needed): checked with `file` and run under
#                                      qemu-user; no tests. With --armv7 or --aarch64: that one only.
#   scripts/arm.sh --old-glibc         release binaries linked against glibc 2.17 symbols (armv7 and
#                                      aarch64 gnu), for boards whose glibc is older than this
#                                      machine's (Raspberry Pi OS bullseye, Ubuntu 20.04 / JetPack 5):
#                                      cargo-zigbuild with zig as the linker, both installed under
#                                      target/tools on first use (PyPI's ziglang, crates.io's
#                                      cargo-zigbuild); checked with objdump and run under qemu-user.
#
# Tests run in the release profile on purpose: the test builds then reuse the dependencies
# (tokio, mavlink's generated dialects) already compiled for the release binary, which halves a
# cold run, and they exercise the code generation that ships. Parallelism: cargo's own
# CARGO_BUILD_JOBS. See docs/deploy-arm.md.
set -euo pipefail
cd "$(dirname "$0")/.."

want_armv7=0
want_aarch64=0
install_only=0
want_musl=0
want_old_glibc=0
for a in "$@"; do
  case "$a" in
    --musl) want_musl=1 ;;
    --old-glibc) want_old_glibc=1 ;;
    --armv7) want_armv7=1 ;;
    --aarch64) want_aarch64=1 ;;
    --install) install_only=1 ;;
    -h | --help) sed -n '2,26p' "$0"; exit 0 ;;
    *) echo "arm.sh: unknown argument '$a' (try --help)" >&2; exit 2 ;;
  esac
done

t0=$SECONDS
stage() { echo "== arm: $* (t=$((SECONDS - t0))s)"; }
die() { echo "arm.sh: $*" >&2; exit 1; }

# ---------------------------------------------------------------- --old-glibc: glibc 2.17 floor
# The gnu targets as usual, but linked by zig against glibc 2.17's symbol versions, so the binary
# loads on any glibc from 2.17 on (this machine's cross gcc would tie it to 2.36). Used where the
# musl standard library is unavailable (rustup's armv7 musl rust-std is missing on some mirrors).
if [ "$want_old_glibc" = 1 ]; then
  if [ "$want_armv7" = 0 ] && [ "$want_aarch64" = 0 ]; then want_armv7=1; want_aarch64=1; fi
  glibc=2.17
  target_dir="${CARGO_TARGET_DIR:-$(cargo metadata --no-deps --format-version 1 |
    sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')}"
  tools="$target_dir/tools"
  if [ ! -x "$tools/zig-venv/bin/python" ] || ! "$tools/zig-venv/bin/python" -m ziglang version >/dev/null 2>&1; then
    stage "installing zig (PyPI ziglang) into $tools/zig-venv"
    python3 -m venv "$tools/zig-venv"
    "$tools/zig-venv/bin/pip" install --quiet --disable-pip-version-check ziglang || die "pip install ziglang failed"
  fi
  if [ ! -x "$tools/cargo/bin/cargo-zigbuild" ]; then
    stage "installing cargo-zigbuild into $tools/cargo"
    cargo install --quiet --locked --root "$tools/cargo" cargo-zigbuild || die "cargo install cargo-zigbuild failed"
  fi
  export PATH="$tools/cargo/bin:$tools/zig-venv/bin:$PATH"
  for t in $([ "$want_armv7" = 1 ] && echo armv7-unknown-linux-gnueabihf) $([ "$want_aarch64" = 1 ] && echo aarch64-unknown-linux-gnu); do
    rustup target list --installed | grep -qx "$t" || rustup target add "$t" || die "rustup target add $t failed"
    [ "$install_only" = 1 ] && continue
    stage "$t: cargo zigbuild --release (glibc $glibc)"
    cargo zigbuild --quiet --release --target "$t.$glibc" -p companion --bin companion
    bin="$target_dir/$t/release/companion"
    newest="$(objdump -T "$bin" | grep -oE 'GLIBC_[0-9.]+' | sed 's/GLIBC_//' | sort -V | tail -1)"
    echo "   newest glibc symbol version: $newest"
    [ "$(printf '%s\n%s\n' "$newest" "$glibc" | sort -V | tail -1)" = "$glibc" ] || die "$t: needs glibc $newest (> $glibc)"
    case "$t" in armv7-*) qemu=qemu-arm; sysroot=/usr/arm-linux-gnueabihf ;; aarch64-*) qemu=qemu-aarch64; sysroot=/usr/aarch64-linux-gnu ;; esac
    if [ -e "$sysroot/lib" ]; then
      "$qemu" -L "$sysroot" "$bin" simulate --json --no-log --steps 20 >/dev/null || die "$t: companion simulate failed under $qemu"
      echo "   $qemu companion simulate: ok"
    else
      echo "   (no $sysroot here: run scripts/arm.sh --install to run it under $qemu)"
    fi
    echo "   size: $(stat -c %s "$bin") bytes as built ($bin)"
  done
  stage "done"
  exit 0
fi

# ---------------------------------------------------------------- --musl: static binaries
# Fully static (musl libc inside, crt-static), so they run on any ARM Linux whatever its glibc:
# Raspberry Pi OS bullseye (glibc 2.31), Ubuntu 20.04 / JetPack 5 (2.31), older. Linked with the
# rust-lld that ships with the toolchain against rustup's self-contained musl objects.
if [ "$want_musl" = 1 ]; then
  musl_targets=()
  if [ "$want_armv7" = 0 ] && [ "$want_aarch64" = 0 ]; then want_armv7=1; want_aarch64=1; fi
  [ "$want_armv7" = 1 ] && musl_targets+=(armv7-unknown-linux-musleabihf)
  [ "$want_aarch64" = 1 ] && musl_targets+=(aarch64-unknown-linux-musl)
  command -v rustup >/dev/null || die "--musl needs rustup (for the musl standard library of each target)"
  if ! command -v qemu-arm >/dev/null || ! command -v qemu-aarch64 >/dev/null; then
    stage "installing qemu-user (to run the binaries here)"
    sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
    $sudo apt-get install -y -q --no-upgrade --no-install-recommends qemu-user >/dev/null || die "apt-get install qemu-user failed"
  fi
  target_dir="${CARGO_TARGET_DIR:-$(cargo metadata --no-deps --format-version 1 |
    sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')}"
  # A strip that reads ARM ELF: llvm-strip (any LLVM), else the toolchain's rust-objcopy (needs
  # the llvm-tools component's libLLVM); without one, the sizes are reported unstripped.
  strip_cmd=()
  if command -v llvm-strip >/dev/null; then
    strip_cmd=(llvm-strip -o)
  else
    objcopy="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/rust-objcopy"
    "$objcopy" --version >/dev/null 2>&1 && strip_cmd=("$objcopy" --strip-all)
  fi
  for t in "${musl_targets[@]}"; do
    if ! rustup target list --installed | grep -qx "$t"; then
      stage "rustup target add $t"
      rustup target add "$t" || die "rustup target add $t failed (rustup's dist server unreachable, or no rust-std for $t in this toolchain)"
    fi
    [ "$install_only" = 1 ] && continue
    env_t="$(tr 'a-z-' 'A-Z_' <<<"$t")"
    stage "$t: cargo build --release (static, rust-lld)"
    env "CARGO_TARGET_${env_t}_LINKER=rust-lld" \
      "CARGO_TARGET_${env_t}_RUSTFLAGS=-C linker-flavor=ld.lld -C link-self-contained=yes -C target-feature=+crt-static" \
      cargo build --quiet --release --target "$t" -p companion --bin companion
    bin="$target_dir/$t/release/companion"
    info="$(file -b "$bin")"
    echo "   file: $info"
    grep -q "statically linked" <<<"$info" || die "$t: $bin is not statically linked"
    case "$t" in armv7-*) qemu=qemu-arm ;; aarch64-*) qemu=qemu-aarch64 ;; esac
    "$qemu" "$bin" --help >/dev/null || die "$t: companion --help failed under $qemu"
    "$qemu" "$bin" simulate --json --no-log --steps 20 >/dev/null || die "$t: companion simulate failed under $qemu"
    echo "   $qemu companion --help and simulate: ok"
    if [ "${#strip_cmd[@]}" -gt 0 ]; then
      if [ "${strip_cmd[0]}" = llvm-strip ]; then "${strip_cmd[@]}" "$bin.stripped" "$bin"; else "${strip_cmd[@]}" "$bin" "$bin.stripped"; fi
      echo "   size: $(stat -c %s "$bin") bytes as built, $(stat -c %s "$bin.stripped") bytes stripped ($bin.stripped)"
    else
      echo "   size: $(stat -c %s "$bin") bytes as built (no llvm-strip here to strip a copy)"
    fi
  done
  stage "done"
  exit 0
fi

[ "$want_aarch64" = 1 ] || want_armv7=1

# ---------------------------------------------------------------- install what is missing
# Debian package -> a file it provides that we use (checked instead of asking dpkg, so a tool
# installed some other way also counts).
declare -A provides=([qemu-user]=/usr/bin/qemu-arm)
if [ "$want_armv7" = 1 ]; then
  provides[gcc-arm-linux-gnueabihf]=/usr/bin/arm-linux-gnueabihf-gcc
  provides[libc6-dev-armhf-cross]=/usr/arm-linux-gnueabihf/lib/libc.so
fi
if [ "$want_aarch64" = 1 ]; then
  provides[gcc-aarch64-linux-gnu]=/usr/bin/aarch64-linux-gnu-gcc
  provides[libc6-dev-arm64-cross]=/usr/aarch64-linux-gnu/lib/libc.so
fi
missing=()
for pkg in "${!provides[@]}"; do
  [ -e "${provides[$pkg]}" ] || missing+=("$pkg")
done
if [ "${#missing[@]}" -gt 0 ]; then
  stage "installing Debian packages: ${missing[*]}"
  command -v apt-get >/dev/null || die "missing ${missing[*]} and no apt-get here: install the cross gcc, ARM libc and qemu-user by hand (docs/deploy-arm.md)"
  sudo=""
  if [ "$(id -u)" != 0 ]; then
    command -v sudo >/dev/null || die "missing ${missing[*]}: need root (or sudo) to apt-get install them"
    sudo="sudo"
  fi
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -q >/dev/null || die "apt-get update failed (no network to Debian's mirror?)"
  $sudo apt-get install -y -q --no-upgrade --no-install-recommends "${missing[@]}" >/dev/null ||
    die "apt-get install ${missing[*]} failed"
  for pkg in "${missing[@]}"; do
    [ -e "${provides[$pkg]}" ] || die "installed $pkg but ${provides[$pkg]} is still missing"
  done
fi

targets=()
[ "$want_armv7" = 1 ] && targets+=(armv7-unknown-linux-gnueabihf)
[ "$want_aarch64" = 1 ] && targets+=(aarch64-unknown-linux-gnu)
installed_targets="$(rustup target list --installed 2>/dev/null || true)"
for t in "${targets[@]}"; do
  if ! grep -qx "$t" <<<"$installed_targets"; then
    stage "rustup target add $t"
    command -v rustup >/dev/null || die "no rustup: the standard library for $t cannot be added (install it for your toolchain by hand)"
    rustup target add "$t" || die "rustup target add $t failed (rustup's dist server unreachable?)"
  fi
done
[ "$install_only" = 1 ] && { stage "install done"; exit 0; }

target_dir="${CARGO_TARGET_DIR:-$(cargo metadata --no-deps --format-version 1 |
  sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')}"
[ -n "$target_dir" ] || die "could not find cargo's target directory"

# ---------------------------------------------------------------- per target
run_target() {
  local t="$1" qemu sysroot strip
  case "$t" in
    armv7-*) qemu="qemu-arm"; sysroot=/usr/arm-linux-gnueabihf; strip="arm-linux-gnueabihf-strip" ;;
    aarch64-*) qemu="qemu-aarch64"; sysroot=/usr/aarch64-linux-gnu; strip="aarch64-linux-gnu-strip" ;;
  esac

  # One package set and one target selection for both commands: cargo then resolves features
  # once (dev-dependencies switch on extra features of shared crates such as serde, which would
  # otherwise rebuild mavlink and tokio a second time); `cargo test` then compiles only the
  # unit-test harnesses (cfg(test) builds of the libraries) on top.
  local sel=(--release --target "$t" -p companion -p companion-core -p companion-link -p companion-testkit -p bayes_net -p mdp_engine -p fpga_model -p panorama)
  # Which integration tests run under qemu: not the source guards (their header says "Source
  # guard:": they read the repository's text, which no target changes; the host runs them), and
  # those that start the companion binary as a child process (CARGO_BIN_EXE_*) only when the kernel
  # can exec an ARM ELF, i.e. qemu is registered with binfmt_misc (else the host's `cargo test
  # --workspace` runs them). The rest run under qemu: the libraries' and binaries' unit tests too.
  local binfmt=0 picked name what
  [ -e "/proc/sys/fs/binfmt_misc/$qemu" ] && binfmt=1
  picked="$(cargo metadata --no-deps --format-version 1 | python3 -c '
import json, sys
binfmt = sys.argv[1] == "1"
pkgs = {"companion", "companion-core", "companion-link", "companion-testkit", "bayes_net", "mdp_engine", "fpga_model", "panorama"}
for p in json.load(sys.stdin)["packages"]:
    for t in p["targets"] if p["name"] in pkgs else []:
        if "test" in t["kind"]:
            src = open(t["src_path"], encoding="utf-8").read()
            if "//! Source guard:" in src:
                print("host " + t["name"])
            elif "CARGO_BIN_EXE" in src and not binfmt:
                print("skip " + t["name"])
            else:
                print("run " + t["name"])
' "$binfmt")"
  sel+=(--lib --bins)
  local host=() skipped=()
  while read -r what name; do
    case "$what" in
      run) sel+=(--test "$name") ;;
      host) host+=("$name") ;;
      skip) skipped+=("$name") ;;
    esac
  done <<<"$picked"
  [ "${#host[@]}" -eq 0 ] || echo "   on the host only (source guards): ${host[*]}"
  [ "${#skipped[@]}" -eq 0 ] || echo "   not under qemu (start the binary; no binfmt_misc): ${skipped[*]}"
  stage "$t: cargo build --release: companion binary + test binaries"
  cargo build --quiet "${sel[@]}"
  stage "$t: cargo test (release profile) under $qemu: engines + companion (unit and integration tests)"
  # Every suite runs (--no-fail-fast); a failure does not stop the smoke run and the size report
  # below either; the script still exits non-zero at the end.
  # a quarter of the fuzz corpus under qemu (its replay was 170 of the 460 s the tests take there); all of it runs
  # natively in the test command's Rust stage, with overflow checks (docs/fuzzing.md)
  echo "   fuzz corpus under $qemu: every ${FUZZ_CORPUS_STRIDE:-4}th input (FUZZ_CORPUS_STRIDE), the regressions all"
  if ! FUZZ_CORPUS_STRIDE=${FUZZ_CORPUS_STRIDE:-4} cargo test --quiet --no-fail-fast "${sel[@]}" 2>&1; then
    echo "arm.sh: $t: tests FAILED (the binary checks below still run)" >&2
    failed+=("$t tests")
  fi

  local bin="$target_dir/$t/release/companion"
  stage "$t: the binary under $qemu"
  local run=("$qemu" -L "$sysroot" "$bin")
  "${run[@]}" --help >/dev/null || die "$t: companion --help failed under $qemu"
  # `simulate --json --runs 3` once the subcommand has those flags; until then --help is the smoke.
  local sim_help
  sim_help="$("${run[@]}" simulate --help 2>/dev/null || true)"
  if grep -q -- '--runs' <<<"$sim_help" && grep -q -- '--json' <<<"$sim_help"; then
    local out extra=()
    # No run folder from a smoke test.
    grep -q -- '--no-log' <<<"$sim_help" && extra+=(--no-log)
    out="$("${run[@]}" simulate --json --runs 3 "${extra[@]}")" || die "$t: companion simulate --json --runs 3 failed"
    python3 -c 'import json,sys; json.loads(sys.stdin.read())' <<<"$out" 2>/dev/null ||
      printf '%s\n' "$out" | python3 -c 'import json,sys; [json.loads(l) for l in sys.stdin if l.strip()]' ||
      die "$t: simulate --json printed something that is not JSON (nor JSON lines)"
    echo "   simulate --json --runs 3: ok ($(wc -c <<<"$out") bytes of JSON)"
  else
    echo "   companion --help: ok (simulate has no --json/--runs yet)"
  fi

  local stripped="$target_dir/$t/release/companion.stripped"
  "$strip" -o "$stripped" "$bin"
  echo "   size: $(stat -c %s "$bin") bytes as built, $(stat -c %s "$stripped") bytes stripped ($stripped)"
  check_size "$t" "$(stat -c %s "$stripped")"
}

# The onboard binary's size is a contract (issue 38: the ground side's DataFusion and Arrow stay out
# of it): the stripped armv7 `companion` within 2 % of the figure docs/deploy-arm.md gives. A change
# that moves it further updates that figure, on purpose, in the same commit.
check_size() {
  [ "$1" = armv7-unknown-linux-gnueabihf ] || return 0
  local doc expected
  doc="$(dirname "$0")/../docs/deploy-arm.md"
  expected="$(sed -n 's/^| armv7 `companion`, stripped (what goes on the board) | \([0-9 ]*\) bytes.*/\1/p' "$doc" | tr -d ' ')"
  if [ -z "$expected" ]; then
    echo "arm.sh: docs/deploy-arm.md gives no stripped armv7 size to check against" >&2
    failed+=("size: no documented figure")
    return 0
  fi
  if ! python3 -c 'import sys; a, e = int(sys.argv[1]), int(sys.argv[2]); sys.exit(abs(a - e) > 0.02 * e)' "$2" "$expected"; then
    echo "arm.sh: stripped armv7 companion is $2 bytes, docs/deploy-arm.md says $expected (more than 2 % apart): update the figure if the change is meant" >&2
    failed+=("size $2 vs $expected")
  else
    echo "   size check: $2 bytes stripped, within 2 % of docs/deploy-arm.md's $expected"
  fi
}

failed=()
for t in "${targets[@]}"; do
  run_target "$t"
done
if [ "${#failed[@]}" -gt 0 ]; then
  stage "FAILED: ${failed[*]}"
  exit 1
fi
stage "done"
