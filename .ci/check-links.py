#!/usr/bin/env python3
"""Checks the relative links of the project's Markdown (python3, standard library only).

    python3 .ci/check-links.py            (from anywhere; checks the files below)
    python3 .ci/check-links.py FILE...    (only these files)

Files: README.md, CHANGELOG.md, every Markdown file under docs/ (docs/guide/ included),
firmware/README.md and benches/README.md. Every relative link `[text](path)` and
`[text](path#anchor)` (and reference definitions `[label]: path`) must name a file or folder
that exists, relative to the linking file (a leading `/` means the repository root); an
anchor must be a heading of the target Markdown file, slugged as GitHub does (lower case,
punctuation other than `-` and `_` removed, spaces to `-`, repeats numbered `-1`, `-2`),
or an explicit `<a name=...>` / `id=...`. `#anchor` alone refers to the linking file.
External links (http, https, mailto, ...) are counted, not fetched. Links inside code
blocks and inline code are not links.

Exit status 1 with every broken link as `file:line: target: reason`; on success
`N links checked`.
"""
import os
import re
import sys
import unicodedata

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_FILES = ["README.md", "CHANGELOG.md", "firmware/README.md", "benches/README.md"]

INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*(<[^>]*>|[^()\s]*(?:\([^()\s]*\)[^()\s]*)*)(?:\s+(?:\"[^\"]*\"|'[^']*'|\([^()]*\)))?\s*\)")
REF_DEF = re.compile(r"^ {0,3}\[([^\]]+)\]:\s*(<[^>]*>|\S+)")
HTML_ANCHOR = re.compile(r"<a\s+[^>]*(?:name|id)\s*=\s*[\"']([^\"']+)[\"']", re.I)
HTML_ID = re.compile(r"\bid\s*=\s*[\"']([^\"']+)[\"']", re.I)
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")
FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
ATX = re.compile(r"^ {0,3}(#{1,6})(?:[ \t]+(.*?))?[ \t]*$")
SETEXT = re.compile(r"^ {0,3}(=+|-+)[ \t]*$")


def markdown_files():
    files = [f for f in DEFAULT_FILES if os.path.exists(os.path.join(ROOT, f))]
    for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, "docs")):
        dirnames.sort()
        for name in sorted(filenames):
            if name.endswith(".md"):
                files.append(os.path.relpath(os.path.join(dirpath, name), ROOT))
    return files


def text_lines(path):
    """The file's lines with code blocks blanked and inline code removed (line numbers kept)."""
    with open(path, encoding="utf-8") as f:
        lines = f.read().split("\n")
    out, fence = [], None
    for line in lines:
        m = FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)[0] * len(m.group(1))
            out.append("")
            continue
        if fence is not None:
            if m and m.group(1).startswith(fence) and line.strip().strip(fence[0]) == "":
                fence = None
            out.append("")
            continue
        out.append(strip_inline_code(line))
    return out


def strip_inline_code(line):
    # a run of n backticks closes at the next run of exactly n backticks
    res, i = [], 0
    while i < len(line):
        if line[i] == "`":
            j = i
            while j < len(line) and line[j] == "`":
                j += 1
            ticks = line[i:j]
            end = re.compile(r"(?<!`)" + ticks + r"(?!`)").search(line, j)
            if end:
                res.append(" ")
                i = end.end()
                continue
            res.append(ticks)
            i = j
            continue
        res.append(line[i])
        i += 1
    return "".join(res)


def heading_text(raw):
    """The text GitHub renders for a heading's source (links to their text, markup removed)."""
    t = re.sub(r"[ \t]+#+[ \t]*$", "", raw.strip())
    if re.fullmatch(r"#+", t):
        t = ""
    t = re.sub(r"!\[([^\]]*)\]\([^)]*\)", r"\1", t)
    t = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", t)
    t = re.sub(r"\[([^\]]*)\]\[[^\]]*\]", r"\1", t)
    t = re.sub(r"<[^>]+>", "", t)
    t = t.replace("`", "")
    t = re.sub(r"(\*+|(?<!\w)_+|_+(?!\w))", "", t)
    return t.replace("\\", "")


def slug(text):
    """github-slugger: lower case, keep letters, digits, marks, '-', '_' and spaces; spaces to '-'."""
    out = []
    for ch in text.lower():
        cat = unicodedata.category(ch)
        if ch in "-_ " or cat[0] in "LNM":
            out.append("-" if ch == " " else ch)
    return "".join(out)


_anchor_cache = {}


def anchors(path):
    """Every anchor of a Markdown file: heading slugs (numbered repeats) and HTML ids."""
    if path in _anchor_cache:
        return _anchor_cache[path]
    found, seen = set(), {}
    with open(path, encoding="utf-8") as f:
        raw_lines = f.read().split("\n")
    lines = text_lines(path)
    prev = ""
    for i, line in enumerate(lines):
        heading = None
        m = ATX.match(line)
        if m:
            heading = heading_text(raw_lines[i].lstrip()[len(m.group(1)):])
        elif SETEXT.match(line) and prev.strip() and not prev.lstrip().startswith(("|", "-", "*", ">")):
            heading = heading_text(raw_lines[i - 1])
        if heading is not None:
            s = slug(heading)
            if s in seen:
                seen[s] += 1
                s2 = f"{s}-{seen[s]}"
                while s2 in seen:
                    seen[s] += 1
                    s2 = f"{s}-{seen[s]}"
                seen[s2] = 0
                s = s2
            else:
                seen[s] = 0
            found.add(s)
        for rx in (HTML_ANCHOR, HTML_ID):
            for a in rx.findall(raw_lines[i]):
                found.add(a)
        prev = line
    _anchor_cache[path] = found
    return found


def links(path):
    """(line number, target) of every link in a Markdown file, in line order (link text may
    span lines)."""
    lines = text_lines(path)
    text = "\n".join(lines)
    found = [(text.count("\n", 0, m.start()) + 1, m.group(1)) for m in INLINE_LINK.finditer(text)]
    for n, line in enumerate(lines, 1):
        m = REF_DEF.match(line)
        if m and not m.group(1).startswith("^"):
            found.append((n, m.group(2)))
    return sorted(found, key=lambda x: x[0])


def check(files):
    checked, external, broken = 0, 0, []
    for rel in files:
        path = os.path.join(ROOT, rel)
        if not os.path.isfile(path):
            broken.append(f"{rel}: the file does not exist")
            continue
        for n, target in links(path):
            target = target.strip()
            if target.startswith("<") and target.endswith(">"):
                target = target[1:-1].strip()
            if SCHEME.match(target):
                external += 1
                continue
            checked += 1
            where = f"{rel}:{n}: {target}"
            if not target:
                broken.append(f"{where}: empty link")
                continue
            file_part, _, anchor = target.partition("#")
            file_part = re.sub(r"%20", " ", file_part.split("?")[0])
            if file_part:
                base = ROOT if file_part.startswith("/") else os.path.dirname(path)
                dest = os.path.normpath(os.path.join(base, file_part.lstrip("/")))
                if not (dest == ROOT or dest.startswith(ROOT + os.sep)):
                    broken.append(f"{where}: leaves the repository")
                    continue
                if not os.path.exists(dest):
                    broken.append(f"{where}: no such file or folder")
                    continue
            else:
                dest = path
            if anchor:
                if os.path.isdir(dest):
                    broken.append(f"{where}: an anchor on a folder")
                elif not dest.endswith(".md"):
                    broken.append(f"{where}: an anchor on a file that is not Markdown")
                elif anchor not in anchors(dest) and anchor.lower() not in anchors(dest):
                    broken.append(f"{where}: no heading or id '{anchor}' in {os.path.relpath(dest, ROOT)}")
    return checked, external, broken


def main(argv):
    files = argv[1:] or markdown_files()
    checked, external, broken = check(files)
    if broken:
        for b in broken:
            print(b)
        sys.stdout.flush()
        print(f"{len(broken)} broken of {checked} links checked ({len(files)} files)", file=sys.stderr)
        return 1
    print(f"{checked} links checked")
    print(f"({len(files)} files; {external} external links not fetched)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
