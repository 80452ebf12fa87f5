#!/usr/bin/env python3
"""Attributes the firmware's control interrupt, as traced by the firmware-in-the-loop
suite, to the drive's step and the interrupt's own work.

usage: python3 benches/attribute_isr.py TRACE ELF

TRACE is one of the `target/fil-isr-trace-<phase>.txt` files `bash firmware/fil/ci.sh`
writes (one line per interrupt: the executed addresses), ELF the firmware it traced
(`target/thumbv7em-none-eabihf/firmware/acim-firmware-power-stage.elf`, built with
debug line tables by `firmware/check.sh`). Each executed instruction is mapped to its
inlined call chain with `addr2line -i` (LLVM's or GNU binutils') and counted in the
first group whose function-name fragment the chain contains. Instructions per
interrupt, averaged over the trace; the cycle weights are `acim-bench --weigh-isr`'s.
"""
import re
import shutil
import subprocess
import sys
from collections import Counter, defaultdict

# (group, function-name fragments: any one in the chain matches); the first wins
GROUPS = [
    ("the drive's fast step (Drive::step_fast)", ["Drive$LT$S$C$N$C$O$C$M$GT$::step_fast"]),
    ("ADC counts to amperes and volts (Converter::convert)", ["Converter::convert"]),
    ("duty writes (write_duties)", ["write_duties"]),
    ("telemetry hand-off and status (publish)", ["control_isr::publish"]),
    ("samples, flags, break and sequence checks, MOE (stage::control_period)", ["stage::control_period"]),
]
OTHER = "entry: the slow task's gate, the swap claim, commands, cycle counter"


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    trace, elf = sys.argv[1:3]
    counts, interrupts = Counter(), 0
    with open(trace) as f:
        for line in f:
            if line.strip():
                interrupts += 1
                counts.update(int(a, 16) for a in line.split())
    if not interrupts:
        sys.exit(f"{trace}: no interrupts")
    tool = shutil.which("llvm-addr2line") or shutil.which("addr2line")
    if not tool:
        sys.exit("needs llvm-addr2line or addr2line")
    addrs = sorted(counts)
    out = subprocess.run([tool, "-e", elf, "-i", "-f", "-C", "-a"] + [hex(a) for a in addrs],
                         capture_output=True, text=True, check=True).stdout.splitlines()
    chains, cur, i = defaultdict(list), None, 0
    while i < len(out):
        if out[i].startswith("0x"):
            cur = int(out[i], 16)
            i += 1
            continue
        chains[cur].append(out[i])
        i += 2
    per = defaultdict(float)
    for a in addrs:
        names = [re.sub(r"::h[0-9a-f]{16}", "", n) for n in chains[a]]
        group = next((g for g, frags in GROUPS
                      if any(fr in n for fr in frags for n in names)), OTHER)
        per[group] += counts[a] / interrupts
    total = sum(per.values())
    print(f"{trace}: {interrupts} interrupts, {total:.1f} instructions each on average")
    print("| part | instructions per interrupt |\n|---|---|")
    for g, _ in GROUPS:
        print(f"| {g} | {per[g]:.1f} |")
    print(f"| {OTHER} | {per[OTHER]:.1f} |")


if __name__ == "__main__":
    main()
