#!/usr/bin/env bash
# Builds the firmware in both modes (release, thumbv7em-none-eabihf), prints flash/RAM
# use (llvm-size), and fails if the control interrupt can reach a panic or f64 routine,
# if it is not in CCM SRAM, or if a budget (flash 64 KiB, static RAM 16 KiB) is exceeded.
#
#   firmware/check.sh [--warn-only]     (from anywhere; uses the pinned toolchain)
#
# Needs the rustup components llvm-tools (rust-toolchain.toml lists it) and python3.
set -euo pipefail
cd "$(dirname "$0")/.."
TARGET=thumbv7em-none-eabihf
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}"
HOST=$(rustc -vV | sed -n 's/^host: //p')
BIN="$(rustc --print sysroot)/lib/rustlib/$HOST/bin"
[ -x "$BIN/llvm-objdump" ] || { echo "llvm-tools missing: rustup component add llvm-tools" >&2; exit 2; }
OUT="$CARGO_TARGET_DIR/$TARGET/release"
status=0
for mode in power-stage selftest; do
  # the self-test's motor model (acim_plant, and the memclr of its state) runs from flash
  # by design (firmware/README.md); nothing else reachable from an interrupt may
  if [ "$mode" = selftest ]; then
    feat=(--features selftest); isr=TIM6_DACUNDER; allow=(--allow-flash='^_ZN10acim_plant|^__aeabi_mem')
  else
    feat=(); isr=ADC1_2; allow=()
  fi
  echo "== acim-firmware, $mode build"
  cargo build --release -p acim-firmware --target "$TARGET" "${feat[@]}"
  cp "$OUT/acim-firmware" "$OUT/acim-firmware-$mode.elf"
  "$BIN/llvm-size" "$OUT/acim-firmware-$mode.elf"
  python3 firmware/fwcheck.py "$OUT/acim-firmware-$mode.elf" "$isr" "$BIN" "${allow[@]}" "$@" || status=1
done
echo "== bring-up numbers -> firmware/bringup.md"
cargo run -q -p acim-firmware-core --example bringup > firmware/bringup.md
cat firmware/bringup.md
exit $status
