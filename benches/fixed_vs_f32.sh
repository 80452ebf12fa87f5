#!/usr/bin/env bash
# Fixed-point vs f32 instruction counts of the control step, on the same cores under QEMU:
# Cortex-M3 (thumbv7m-none-eabi, f32 in software) on netduino2 and Cortex-M4F
# (thumbv7em-none-eabihf, hardware f32) on netduinoplus2. See src/bin/fixed_vs_f32.rs.
#   bash benches/fixed_vs_f32.sh          (from anywhere; needs qemu-system-arm)
set -euo pipefail
shopt -s inherit_errexit # a failed build inside $(run ...) stops the script
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}"
build() { cargo build -q -p acim-bench --profile firmware --target "$1" --bin acim-bench-fixed; }
run() { # target machine cpu
  timeout 300 qemu-system-arm -machine "$2" -cpu "$3" -nographic -monitor none -serial none \
    -semihosting-config enable=on,target=native -icount shift=4 \
    -kernel "$CARGO_TARGET_DIR/$1/firmware/acim-bench-fixed"
}
build thumbv7m-none-eabi
build thumbv7em-none-eabihf
# the two emulations are independent: run them side by side (icount makes the counts
# independent of the host's load)
out=$(mktemp -d)
run thumbv7m-none-eabi netduino2 cortex-m3 > "$out/m3" & p3=$!
run thumbv7em-none-eabihf netduinoplus2 cortex-m4 > "$out/m4" & p4=$!
wait $p3; wait $p4
m3=$(cat "$out/m3"); m4=$(cat "$out/m4"); rm -rf "$out"
mean() { # output arithmetic region
  printf '%s\n' "$1" | sed -n "s/.*arithmetic=$2 region=$3 .*insn_mean=\([0-9.]*\).*/\1/p"
}
printf '%-18s %14s %12s %14s %12s\n' region "M3 f32 (soft)" "M3 fixed" "M4F f32 (hw)" "M4F fixed"
for r in observer_alone observer_reduced clarke_park fault_checks rs_estimator flux_slip speed_pi current_pi svpwm drive_step; do
  a=$(mean "$m3" f32 $r); b=$(mean "$m3" fixed $r); c=$(mean "$m4" f32 $r); d=$(mean "$m4" fixed $r)
  [ -n "$a$b$c$d" ] || { echo "region $r missing from the QEMU output" >&2; exit 1; }
  printf '%-18s %14s %12s %14s %12s\n' "$r" "$a" "$b" "$c" "$d"
done
echo "(mean executed instructions per step, QEMU 7.2 -icount; the M3 f32 figures include the soft-float routines)"
