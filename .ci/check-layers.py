#!/usr/bin/env python3
"""The core crate's layering: no import cycle among its modules, and no block imports the
design or the drive.

Reads every module of crates/acim/src (production code only: a file is cut at its
`#[cfg(test)]` test module, and comment lines are skipped, so doc links do not count) and
collects the modules each one names (`crate::x`, `super::x` in fixed/). Fails on:

- a cycle: two modules that reach each other (strongly connected components of size > 1);
- a block naming `design` or `drive`: a block is any module outside the composition layer
  (the drive, its design and configuration, the controller interface, the commissioning
  and nameplate front ends, the fixed-point drive and its conversion).

Usage: python3 .ci/check-layers.py [crate src dir]
"""
import os
import re
import sys

SRC = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "crates", "acim", "src")

# the composition layer: may import anything below it
COMPOSITION = {
    "lib", "design", "drive", "controller", "commissioning", "nameplate",
    "fixed", "fixed::drive",
}
FORBIDDEN_FOR_BLOCKS = {"design", "drive"}


def modules(src):
    out = {}
    for root, _, files in os.walk(src):
        for f in files:
            if not f.endswith(".rs"):
                continue
            rel = os.path.relpath(os.path.join(root, f), src)[:-3].replace(os.sep, "::")
            if rel.endswith("::mod"):
                rel = rel[: -len("::mod")]
            if rel == "fixed::tests":
                continue  # a test-only file (cfg(test) in fixed/mod.rs)
            out[rel] = os.path.join(root, f)
    return out


def production_text(path):
    lines = open(path, encoding="utf-8").read().split("\n")
    kept = []
    for i, line in enumerate(lines):
        if line.startswith("#[cfg(test)]") and i + 1 < len(lines) and lines[i + 1].startswith("mod tests"):
            break
        if line.lstrip().startswith("//"):
            continue
        kept.append(line)
    return "\n".join(kept)


def references(name, text, known):
    refs = set()
    # `use crate::{a::X, b}` groups and plain paths
    for m in re.finditer(r"\bcrate::\{([^}]*)\}", text):
        for part in m.group(1).split(","):
            head = part.strip().split("::")[0]
            if head:
                refs.add(head)
    for m in re.finditer(r"\bcrate::([a-z_][a-z0-9_]*)(?:::([a-z_][a-z0-9_]*))?", text):
        a, b = m.group(1), m.group(2)
        refs.add(f"{a}::{b}" if b and f"{a}::{b}" in known else a)
    if "::" in name:
        parent = name.rsplit("::", 1)[0]
        for m in re.finditer(r"\bsuper::([a-z_][a-z0-9_]*)", text):
            refs.add(f"{parent}::{m.group(1)}" if f"{parent}::{m.group(1)}" in known else parent)
    refs = {r for r in refs if r in known and r != name}
    # a submodule naming its parent module's items (e.g. `super::PerUnitBases`) depends on
    # the parent file; the parent declaring its submodules is not a dependency
    return refs


def sccs(graph):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(comp)

    sys.setrecursionlimit(10000)
    for v in graph:
        if v not in index:
            visit(v)
    return out


def main():
    mods = modules(SRC)
    known = set(mods)
    graph = {}
    for name, path in mods.items():
        refs = references(name, production_text(path), known)
        if name == "lib" or name == "fixed":
            refs = {r for r in refs if not r.startswith(name + "::")} if name == "fixed" else set()
        graph[name] = refs
    bad = False
    for comp in sccs(graph):
        if len(comp) > 1:
            bad = True
            print("import cycle: " + " <-> ".join(sorted(comp)), file=sys.stderr)
            for a in sorted(comp):
                for b in sorted(graph[a] & set(comp)):
                    print(f"  {a} -> {b}", file=sys.stderr)
    for name, refs in sorted(graph.items()):
        if name in COMPOSITION:
            continue
        for r in sorted(refs & FORBIDDEN_FOR_BLOCKS):
            bad = True
            print(f"block {name} imports {r} (blocks take their own configs and inputs)", file=sys.stderr)
    if bad:
        sys.exit(1)
    blocks = sorted(n for n in graph if n not in COMPOSITION)
    print(f"layers ok: {len(graph)} modules, no import cycle, {len(blocks)} blocks import neither design nor drive")


if __name__ == "__main__":
    main()
