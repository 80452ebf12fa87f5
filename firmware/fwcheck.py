#!/usr/bin/env python3
"""Checks a linked firmware ELF: budgets, placement, and what the control interrupt can reach.

usage: fwcheck.py ELF ISR_SYMBOL BIN_DIR [--warn-only] [--allow-flash=REGEX]

- flash (everything loaded from flash) <= 128 KiB, static RAM (.data + .bss + .uninit +
  .ccmram_uninit) <= 16 KiB. The flash budget was 96 KiB while the settings were meant
  for the last page of a 128 KiB part; the settings pages need the 512 KiB part (below),
  so the image is bounded by bank 1 instead: 128 KiB keeps half of it free. The part is the NUCLEO-G474RE's STM32G474RE (512 KiB,
  dual-bank, 2 KiB pages): the settings pages A and B (board-core/src/settings.rs
  SETTINGS_ADDR, bank 2 pages 126 and 127) exist only on the 512 KiB parts (xE), not on the
  xB (128 KiB) or xC (256 KiB). Checked: both pages lie inside that part's flash, in bank
  2, on a page boundary that matches their page numbers, and above everything the image
  loads;
- the ISR lies in CCM SRAM (0x1000_0000 .. 0x1000_8000);
- call graph from the ISR (direct `bl`/`b` targets in the disassembly, through linker
  thunks): fails if any reachable function is a panic routine or an f64 routine, or lies
  outside CCM SRAM (flash wait states, and a section-name change in ccmram.x would move
  code silently) unless its name matches --allow-flash; lists indirect calls it cannot
  follow;
- worst-case stack of the ISR from the prologues (push / vpush / sub sp) along the deepest
  call path, plus the hardware exception frame.
"""
import re
import subprocess
import sys
from collections import defaultdict

FLASH_BUDGET = 128 * 1024
# the part the settings address needs (STM32G474xE, dual-bank mode: two banks of 256 KiB
# in 2 KiB pages)
PART, PART_FLASH, BANK_BYTES, PAGE_BYTES = "STM32G474xE", 512 * 1024, 256 * 1024, 2048
FLASH_BASE = 0x0800_0000
RAM_BUDGET = 16 * 1024
CCM_LO, CCM_HI = 0x1000_0000, 0x1000_8000

FORBIDDEN = [
    (re.compile(r"panick|panic_|_panic|unwrap_failed|expect_failed|slice_.*fail|index_.*fail|rust_begin_unwind"), "panic"),
    (re.compile(r"^__aeabi_(d|f2d|i2d|ui2d|l2d|ul2d)|^__(add|sub|mul|div|neg)df3$|^__(extendsfdf2|truncdfsf2)$|^__(fix|fixuns)df|^__float(un)?(si|di)df$|^__(eq|ne|lt|le|gt|ge|un)df2$"), "f64"),
    (re.compile(r"3f64|core::f64|_f64_|\$f64|libm.*[^f]$"), "f64?"),
]


def run(*args):
    return subprocess.run(args, check=True, capture_output=True, text=True).stdout


def main():
    argv = [a for a in sys.argv[1:] if not a.startswith("--")]
    warn_only = "--warn-only" in sys.argv
    elf, isr, bindir = argv
    ok = True

    # --- sizes -------------------------------------------------------------------------
    secs = {}
    for line in run(f"{bindir}/llvm-size", "-A", "-d", elf).splitlines():
        m = re.match(r"^(\.\S+)\s+(\d+)\s+(\d+)", line)
        if m:
            secs[m.group(1)] = (int(m.group(2)), int(m.group(3)))
    flash_secs = [".vector_table", ".text.design_in_flash", ".ccmram", ".text", ".rodata", ".data",
                  ".gnu.sgstubs"]
    ram_secs = [".data", ".bss", ".uninit", ".ccmram_uninit"]
    flash = sum(secs.get(s, (0, 0))[0] for s in flash_secs)
    ram = sum(secs.get(s, (0, 0))[0] for s in ram_secs)
    ccm_code = secs.get(".ccmram", (0, 0))[0]
    print(f"  flash      {flash:7d} B ({flash / 1024:.1f} KiB) of {FLASH_BUDGET // 1024} KiB budget")
    print(f"  static RAM {ram:7d} B ({ram / 1024:.1f} KiB) of {RAM_BUDGET // 1024} KiB budget "
          f"(.data {secs.get('.data', (0, 0))[0]}, .bss {secs.get('.bss', (0, 0))[0]}, "
          f".uninit {secs.get('.uninit', (0, 0))[0]}, CCM state {secs.get('.ccmram_uninit', (0, 0))[0]})")
    print(f"  CCM code   {ccm_code:7d} B (copied from flash at start-up, counted in flash)")
    # the control interrupt's state (`control_isr::STATE`): its size and where it lies
    for line in run(f"{bindir}/llvm-nm", "-S", "--defined-only", elf).splitlines():
        m = re.match(r"^([0-9a-f]+) ([0-9a-f]+) [bBdD] \S*control_isr5STATE", line)
        if m:
            addr, size = int(m.group(1), 16), int(m.group(2), 16)
            where = "CCM SRAM" if CCM_LO <= addr < CCM_HI else "SRAM"
            print(f"  control state {size} B in {where}")
    if flash > FLASH_BUDGET:
        print("  FAIL: flash over budget")
        ok = False
    ok &= check_settings_page(elf, bindir)
    if ram > RAM_BUDGET:
        print("  FAIL: static RAM over budget")
        ok = False

    # --- disassembly and call graph ----------------------------------------------------
    dis = run(f"{bindir}/llvm-objdump", "-d", "--no-show-raw-insn", elf)
    # objdump may label a function with a linker symbol at the same address (e.g.
    # __sccmram): prefer the sized symbol from nm
    sized = {}
    for line in run(f"{bindir}/llvm-nm", "-S", "--defined-only", elf).splitlines():
        p = line.split()
        if len(p) == 4 and p[2] in "tTwW":
            a, z = int(p[0], 16), int(p[1], 16)
            if z > sized.get(a, ("", 0))[1]:
                sized[a] = (p[3], z)
    funcs = {}  # name -> dict(addr, calls:set, indirect:int, stack:int)
    cur = None
    head = re.compile(r"^([0-9a-f]+) <(.+)>:$")
    call = re.compile(r"\s(bl|b|b\.w|blx)\s+(?:0x)?[0-9a-f]+ <([^>+]+)(\+0x[0-9a-f]+)?>")
    for line in dis.splitlines():
        m = head.match(line)
        if m:
            cur = sized.get(int(m.group(1), 16), (m.group(2), 0))[0]
            funcs[cur] = {"addr": int(m.group(1), 16), "calls": set(), "indirect": 0, "stack": 0, "n": 0}
            continue
        if cur is None or not line.strip():
            continue
        f = funcs[cur]
        f["n"] += 1
        c = call.search(line)
        if c:
            tgt = c.group(2)
            if tgt != cur:
                f["calls"].add(tgt)
            continue
        if re.search(r"\sblx\s+r\d+|\sbx\s+r(?!14|lr)\d+|\smov\s+pc,", line):
            f["indirect"] += 1
        # prologue stack use (first instructions only)
        if f["n"] <= 12:
            p = re.search(r"\spush(?:\.w)?\s+\{([^}]*)\}", line)
            if p:
                f["stack"] += 4 * len(expand(p.group(1)))
            v = re.search(r"\svpush\s+\{([^}]*)\}", line)
            if v:
                regs = expand(v.group(1))
                f["stack"] += sum(8 if r.startswith("d") else 4 for r in regs)
            s = re.search(r"\ssub(?:\.w)?\s+sp,\s*(?:sp,\s*)?#(0x[0-9a-f]+|\d+)", line)
            if s:
                f["stack"] += int(s.group(1), 0)

    def resolve(name):
        t = re.sub(r"^__\w+?Thunk_", "", name)
        return t if t in funcs else name

    if isr not in funcs:
        print(f"  FAIL: interrupt symbol {isr} not found")
        return 1
    a = funcs[isr]["addr"]
    where = "CCM SRAM" if CCM_LO <= a < CCM_HI else "NOT in CCM SRAM"
    print(f"  {isr} at 0x{a:08x} ({where})")
    if where != "CCM SRAM":
        ok = False

    seen, order, stack = set(), [], [isr]
    while stack:
        n = resolve(stack.pop())
        if n in seen:
            continue
        seen.add(n)
        order.append(n)
        for c in funcs.get(n, {"calls": ()})["calls"]:
            stack.append(c)
    bad = []
    for n in order:
        for rx, kind in FORBIDDEN:
            if rx.search(n):
                bad.append((kind, n))
                break
    indirect = [(n, funcs[n]["indirect"]) for n in order if n in funcs and funcs[n]["indirect"]]
    in_flash = [n for n in order if n in funcs and not (CCM_LO <= funcs[n]["addr"] < CCM_HI)]
    print(f"  reachable from {isr}: {len(order)} functions; outside CCM: {', '.join(in_flash) or 'none'}")
    allow = [a.split("=", 1)[1] for a in sys.argv[1:] if a.startswith("--allow-flash=")]
    allowed = re.compile(allow[0]) if allow else None
    stray = [n for n in in_flash if not (allowed and allowed.search(n))]
    if stray:
        print("  FAIL: reachable from the interrupt but not in CCM SRAM: " + ", ".join(stray))
        ok = False
    if indirect:
        print("  indirect branches not followed: " + ", ".join(f"{n} ({k})" for n, k in indirect))
    if bad:
        print("  FAIL: the control interrupt can reach panic / f64 routines:")
        for kind, n in bad:
            path = find_path(funcs, resolve, isr, n)
            print(f"    [{kind}] {n}\n        via {' -> '.join(path)}")
        ok = False
    else:
        print("  no panic or f64 routine reachable from the interrupt")

    # --- stack ---------------------------------------------------------------------------
    memo = {}

    def depth(n, onpath):
        n = resolve(n)
        if n in memo:
            return memo[n]
        if n in onpath or n not in funcs:
            return 0
        onpath.add(n)
        d = funcs[n]["stack"] + max([depth(c, onpath) for c in funcs[n]["calls"]] or [0])
        onpath.discard(n)
        memo[n] = d
        return d

    d = depth(isr, set())
    frame = 104  # exception entry with FP context (26 words; lazy stacking reserves it)
    print(f"  interrupt stack: {d} B in the handler's call tree + {frame} B exception frame = {d + frame} B "
          f"(static estimate from prologues; direct calls only)")

    if not ok and warn_only:
        print("  (warn-only: not failing)")
        return 0
    return 0 if ok else 1


def settings_constants():
    import os
    src = open(os.path.join(os.path.dirname(os.path.abspath(__file__)),
                            "board-core", "src", "settings.rs")).read()
    def const(name):
        m = re.search(rf"pub const {name}: \w+ = ([0-9_xXa-fA-F]+);", src)
        return int(m.group(1).replace("_", ""), 0)
    return (const("SETTINGS_ADDR"), const("SETTINGS_PAGE_BYTES"), const("SETTINGS_PAGE_NUMBER"),
            const("SETTINGS_PAGES"))


def check_settings_page(elf, bindir):
    """The settings pages (A and B) exist on the part and nothing the image loads reaches
    them."""
    addr, size, page, pages = settings_constants()
    import struct
    data = open(elf, "rb").read()
    phoff, = struct.unpack_from("<I", data, 28)
    phentsize, phnum = struct.unpack_from("<HH", data, 42)
    end = 0
    for i in range(phnum):
        typ, _off, _va, pa, filesz = struct.unpack_from("<5I", data, phoff + i * phentsize)
        if typ == 1 and filesz:                        # PT_LOAD: what the flash holds
            end = max(end, pa + filesz)
    problems = []
    top = addr + pages * size
    if not (FLASH_BASE + BANK_BYTES <= addr and top <= FLASH_BASE + PART_FLASH):
        problems.append(f"0x{addr:08x}..0x{top:08x} is not in bank 2 of the {PART} (512 KiB)")
    if size != PAGE_BYTES or addr != FLASH_BASE + BANK_BYTES + page * PAGE_BYTES:
        problems.append(f"0x{addr:08x} is not bank 2 page {page}")
    if pages != 2 or page + pages > BANK_BYTES // PAGE_BYTES:
        problems.append(f"pages {page}..{page + pages - 1}: not two pages of bank 2")
    if end > addr:
        problems.append(f"the image ends at 0x{end:08x}, above the settings pages")
    for p in problems:
        print(f"  FAIL: settings pages: {p}")
    if not problems:
        print(f"  settings pages A 0x{addr:08x}, B 0x{addr + size:08x} (bank 2 pages {page} and "
              f"{page + 1}) exist on the {PART}; image ends at 0x{end:08x}")
    return not problems


def expand(reglist):
    out = []
    for part in reglist.split(","):
        part = part.strip()
        m = re.match(r"([a-z]+)(\d+)-[a-z]+(\d+)$", part)
        if m:
            out += [f"{m.group(1)}{i}" for i in range(int(m.group(2)), int(m.group(3)) + 1)]
        elif part:
            out.append(part)
    return out


def find_path(funcs, resolve, src, dst):
    prev, queue, seen = {}, [src], {src}
    while queue:
        n = queue.pop(0)
        if n == dst:
            path = [n]
            while path[-1] in prev:
                path.append(prev[path[-1]])
            return list(reversed(path))
        for c in funcs.get(n, {"calls": ()})["calls"]:
            c = resolve(c)
            if c not in seen:
                seen.add(c)
                prev[c] = n
                queue.append(c)
    return [src, "?", dst]


if __name__ == "__main__":
    sys.exit(main())
