#!/usr/bin/env python3
"""Attributes a drive-step profile of acim-bench to the control step's blocks.

usage: python3 benches/attribute.py PROFILE ELF

PROFILE is one of the `results/profile_*_drive_step.txt` files `cargo run -p acim-bench
--release` writes (per executed instruction: executions and estimated cycles per step),
ELF the binary it measured (`target/thumbv7em-none-eabihf/firmware/acim-bench-fw` for the
f32 profile, `.../acim-bench-fixed` for the fixed-point ones; built with debug line
tables, the firmware profile's `debug = true`). Every instruction is mapped to its
inlined call chain with `addr2line -i` (LLVM's or GNU binutils'), and the chain's
function names decide the block (the first rule that matches, in the order below). The
table of benches/README.md ("Why the targets are not met") is this script's output for
the f32 and the M4F fixed-point profile.
"""
import re
import shutil
import subprocess
import sys
from collections import defaultdict

# (block, function-name fragments of the inlined chain: any one matches, "a+b" needs
# both); the first rule that matches wins
RULES = [
    ("modulation: voltage lead (inverse Park angle)", ["small_rotation", "rotate_ahead"]),
    ("supervision: raw-sample gate", ["Supervisor::gate"]),
    ("supervision: estimate plausibility", ["::plausibility"]),
    ("supervision: control monitor, offset drift", ["monitor_control"]),
    ("supervision: stall, blind", ["Supervisor::stall", "Supervisor::blind"]),
    ("feature: field weakening", ["field_weakening", "flux_optimum"]),
    ("feature: regeneration limit", ["regen_limit"]),
    ("feature: running offset tracker", ["OffsetTracker"]),
    ("feature: running inverter tracker", ["InverterTracker", "sign_vector"]),
    ("core: sin/cos", ["sin_cos"]),
    ("core: Clarke, Park, offsets, sample ripple, bus scaling", ["::sense"]),
    ("core: observer (eq. 12)", ["ReducedOrderObserver"]),
    ("core: Rs estimator (eq. 19-20)", ["RsEstimator"]),
    ("core: orientation correction", ["orientation::correction"]),
    ("core: flux model, slip, angle (eq. 13, 8)", ["FluxModel"]),
    ("core: residual filter and other estimate bookkeeping", ["::estimate"]),
    ("core: speed PI", ["::references+update_with_limits"]),
    ("core: speed ramp, hold, magnetizing bookkeeping", ["::references"]),
    ("core: current PIs and decoupling (eq. 9)", ["current_control"]),
    ("core: SVPWM and dead-time compensation", ["Modulator", "::modulate@"]),
    ("telemetry record", ["::record"]),
    ("core: voltage limit, 1/V_dc", ["voltage_limit", "recip", "transient_limit"]),
]
OTHER = "state machine, zero-speed policy, applied-voltage store"


def addr2line():
    for tool in ("llvm-addr2line", "addr2line"):
        path = shutil.which(tool)
        if path:
            return path
    sys.exit("needs llvm-addr2line or addr2line on PATH")


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    prof, elf = sys.argv[1], sys.argv[2]
    rows = []
    for line in open(prof):
        m = re.match(r"\s+([\d.]+)\s+([\d.]+)\s+([0-9a-f]{8})\s", line)
        if m:
            rows.append((float(m.group(1)), float(m.group(2)), int(m.group(3), 16)))
    if not rows:
        sys.exit(f"{prof}: no per-instruction rows")
    out = subprocess.run(
        [addr2line(), "-e", elf, "-i", "-f", "-C", "-a"] + [hex(a) for _, _, a in rows],
        check=True, capture_output=True, text=True,
    ).stdout.splitlines()
    chains, cur, i = {}, None, 0
    while i < len(out):
        if out[i].startswith("0x"):
            cur = int(out[i], 16)
            chains[cur] = []
            i += 1
            continue
        chains[cur].append((out[i], out[i + 1]))
        i += 2
    blocks = defaultdict(lambda: [0.0, 0.0])
    for ins, cyc, addr in rows:
        # outermost call first, each as "function@file:line" (hashes dropped)
        names = " ".join(
            re.sub(r"::h[0-9a-f]{16}", "", f) + "@" + re.sub(r".*/", "", loc).split(" ")[0]
            for f, loc in reversed(chains.get(addr, []))
        )
        block = OTHER
        for name, frags in RULES:
            if any(all(part in names for part in fr.split("+")) for fr in frags):
                block = name
                break
        blocks[block][0] += ins
        blocks[block][1] += cyc
    print("| block | instructions per step | est. cycles per step |")
    print("|---|---|---|")
    total = [0.0, 0.0]
    for prefix in ("core", "modulation", "supervision", "feature", "telemetry", OTHER):
        part = [(k, v) for k, v in blocks.items() if k.startswith(prefix)]
        for k, v in sorted(part, key=lambda kv: -kv[1][1]):
            print(f"| {k} | {v[0]:.0f} | {v[1]:.0f} |")
            total = [total[0] + v[0], total[1] + v[1]]
    core = [sum(v[j] for k, v in blocks.items() if k.startswith(("core", "modulation"))) for j in (0, 1)]
    print(f"| paper's control core (core + voltage lead) | {core[0]:.0f} | {core[1]:.0f} |")
    print(f"| total (with the bench's region markers) | {total[0]:.0f} | {total[1]:.0f} |")


if __name__ == "__main__":
    main()
