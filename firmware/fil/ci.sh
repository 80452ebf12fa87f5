#!/usr/bin/env bash
# Firmware-in-the-loop suite: installs the emulator (Unicorn, pinned), builds both firmware
# ELFs and the board profiles' if they are missing (firmware/check.sh leaves them in
# target/) and the self-test with
# the software sin/cos (for the host/target bit-exactness test), runs the tests.
#
#   bash firmware/fil/ci.sh          (FIL_UPDATE=1 rewrites golden-boot-writes.txt and isr-budget.json)
set -euo pipefail
cd "$(dirname "$0")/../.."
python3 -m pip install --quiet --disable-pip-version-check -r firmware/fil/requirements.txt \
  || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages \
       -r firmware/fil/requirements.txt
OUT="${CARGO_TARGET_DIR:-$PWD/target}/thumbv7em-none-eabihf/firmware"
if [ ! -f "$OUT/acim-firmware-power-stage.elf" ] || [ ! -f "$OUT/acim-firmware-selftest.elf" ]; then
  bash firmware/check.sh
fi
# the board profiles' ELFs (check.sh builds them too; a relink each if only they are missing)
for profile in x-nucleo-ihm16m1 steval-ihm023v3; do
  if [ ! -f "$OUT/acim-firmware-$profile.elf" ]; then
    cargo build --profile firmware -p acim-firmware --target thumbv7em-none-eabihf --features "$profile"
    cp "$OUT/acim-firmware" "$OUT/acim-firmware-$profile.elf"
  fi
done
# the bit-exactness test's third ELF: the self-test with the software sin/cos (always
# rebuilt: cargo relinks only if something changed since the last build of these features)
cargo build --profile firmware -p acim-firmware --target thumbv7em-none-eabihf --features selftest,soft-sincos
cp "$OUT/acim-firmware" "$OUT/acim-firmware-selftest-soft.elf"
mkdir -p "${CARGO_TARGET_DIR:-$PWD/target}"
cd firmware/fil
# one test class per process, as many at once as there are cores (each boots its own
# emulated MCU); FIL_UPDATE=1 runs serially, since it rewrites shared golden files
if [ "${FIL_UPDATE:-}" = 1 ]; then
  python3 -m unittest -v test_fil
else
  python3 run_parallel.py
fi
