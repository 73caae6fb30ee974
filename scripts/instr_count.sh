#!/usr/bin/env bash
# Counts the instructions a command executes, to estimate its time on the SoCKit's Cortex-A9
# (method and assumptions: docs/deploy-arm.md, "Estimating time on the board").
#
#   scripts/instr_count.sh [--ipc X] [--mhz F] [--fn PATTERN] [--] PROGRAM [ARGS...]
#   scripts/instr_count.sh --self-check
#
# PROGRAM's ELF header picks the counter:
#   ARM (armv7) / aarch64 binary -> qemu-user with the plugin scripts/qemu_insn_count.c: the guest
#       instructions the board's core would execute (same binary, same instruction set).
#   host (x86_64) binary          -> valgrind --tool=callgrind: host instructions (Ir), a
#       different instruction set, so only a proxy for the ARM count; with --fn PATTERN
#       (callgrind's --toggle-collect, e.g. '*decision*step*') it counts inside that function
#       and its callees only.
# The whole process is counted (loader, start-up, params loading): to isolate one decision cycle,
# count the same command at two run counts and divide the difference (docs/deploy-arm.md).
# PROGRAM's own output goes to stderr; stdout gets "instructions: N" and the time estimate at
# --mhz (default 925, the SoCKit's A9) for IPC 1 and --ipc (default 0.5, the cautious bound).
# --self-check counts an ARM loop of known length twice and checks the difference is exact.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"

ipc=0.5
mhz=925
fn=""
self_check=0
while [ $# -gt 0 ]; do
  case "$1" in
    --ipc) ipc="$2"; shift 2 ;;
    --mhz) mhz="$2"; shift 2 ;;
    --fn) fn="$2"; shift 2 ;;
    --self-check) self_check=1; shift ;;
    -h | --help) sed -n '2,22p' "$0"; exit 0 ;;
    --) shift; break ;;
    -*) echo "instr_count.sh: unknown option '$1'" >&2; exit 2 ;;
    *) break ;;
  esac
done
die() { echo "instr_count.sh: $*" >&2; exit 1; }

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

target_dir="${CARGO_TARGET_DIR:-$here/../target}"
plugin="$target_dir/qemu-plugin/libinsn_count.so"
build_plugin() {
  if [ ! -e "$plugin" ] || [ "$here/qemu_insn_count.c" -nt "$plugin" ]; then
    mkdir -p "$(dirname "$plugin")"
    cc -O2 -shared -fPIC -o "$plugin" "$here/qemu_insn_count.c" || die "could not build the qemu plugin"
  fi
}

# ELF e_machine (bytes 18-19, little-endian): 0x28 ARM, 0xb7 AArch64, 0x3e x86-64.
elf_machine() { od -An -tx1 -j18 -N2 "$1" | tr -d ' \n'; }

# count PROGRAM ARGS... -> prints the instruction count
count() {
  local prog
  prog="$(command -v "$1" || true)"
  [ -n "$prog" ] && [ -f "$prog" ] || die "no such program: $1"
  shift
  local qemu="" sysroot=""
  case "$(elf_machine "$prog")" in
    2800) qemu=qemu-arm; sysroot=/usr/arm-linux-gnueabihf ;;
    b700) qemu=qemu-aarch64; sysroot=/usr/aarch64-linux-gnu ;;
    3e00) ;;
    *) die "$prog: not an ARM, AArch64 or x86-64 ELF binary" ;;
  esac
  local log="$work/count.log" n
  rm -f "$log"
  if [ -n "$qemu" ]; then
    [ -z "$fn" ] || die "--fn needs a host binary (callgrind); for ARM count two run counts and subtract"
    command -v "$qemu" >/dev/null || die "$qemu missing: run scripts/arm.sh --install"
    build_plugin
    "$qemu" -L "$sysroot" -plugin "$plugin" -d plugin -D "$log" "$prog" "$@" 1>&2 ||
      die "$prog exited with status $?"
    n="$(sed -n 's/^insn_count: \([0-9]*\)$/\1/p' "$log")"
    [ -n "$n" ] || die "qemu printed no count (does this qemu-user support -plugin? see $log)"
  else
    command -v valgrind >/dev/null || die "valgrind missing (apt-get install valgrind)"
    local opts=(--tool=callgrind --callgrind-out-file="$work/callgrind.out")
    [ -z "$fn" ] || opts+=(--collect-atstart=no "--toggle-collect=$fn")
    valgrind "${opts[@]}" "$prog" "$@" 1>&2 2>"$log" || die "$prog exited with status $? (callgrind log: $(tail -3 "$log"))"
    n="$(sed -n 's/^summary: \([0-9]*\)$/\1/p' "$work/callgrind.out")"
    [ -n "$n" ] || n="$(sed -n 's/^totals: \([0-9]*\)$/\1/p' "$work/callgrind.out")"
    [ -n "$n" ] || die "callgrind wrote no total"
  fi
  echo "$n"
}

if [ "$self_check" = 1 ]; then
  command -v arm-linux-gnueabihf-gcc >/dev/null || die "arm-linux-gnueabihf-gcc missing: run scripts/arm.sh --install"
  cat >"$work/loop.c" <<'EOF'
#include <stdlib.h>
/* N iterations of exactly two instructions (subs, bne). */
int main(int argc, char **argv) {
    unsigned n = argc > 1 ? strtoul(argv[1], 0, 10) : 0;
    if (n) __asm__ volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
    return 0;
}
EOF
  arm-linux-gnueabihf-gcc -O2 -o "$work/loop" "$work/loop.c"
  a="$(count "$work/loop" 1000000)"
  b="$(count "$work/loop" 3000000)"
  echo "loop 1e6: $a, loop 3e6: $b, difference: $((b - a)) (expected 4000000)"
  [ $((b - a)) = 4000000 ] || die "self-check failed"
  echo "self-check ok"
  exit 0
fi

[ $# -gt 0 ] || die "usage: instr_count.sh [--ipc X] [--mhz F] [--fn PATTERN] [--] PROGRAM [ARGS...]"
n="$(count "$@")"
echo "instructions: $n"
python3 - "$n" "$mhz" "$ipc" <<'EOF'
import sys
n, mhz, ipc = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
t1 = n / (mhz * 1e6) * 1e3
print(f"estimate at {mhz:g} MHz: {t1:.3f} ms at IPC 1, {t1 / ipc:.3f} ms at IPC {ipc:g}")
EOF
