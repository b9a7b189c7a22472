#!/usr/bin/env python3
"""The import graph between the top-level modules of the polydem library crate.

A top-level module is `src/<name>.rs` or `src/<name>/`. An edge A -> B is a path into B from code
of A: `crate::B...`, a `use crate::{B, ...}` group, or a `super::` chain that climbs out of A to
the crate root and names B. Comments, strings and `#[cfg(test)] mod` blocks are left out, and
so is the binary (`src/main.rs`, which sees the library as `polydem::`, from outside).

Prints the graph as a Mermaid `graph LR` block, the largest source files of src/ and cuda/ by
line count, and every import cycle: each strongly connected component of more than one module,
with the file:line of every edge inside it, and its elementary cycles. Exits with status 1 when
there is a cycle.

    scripts/module_graph.py              graph, largest files, cycles
    scripts/module_graph.py --markdown   the "Architecture at a glance" block of docs/design.md
    scripts/module_graph.py --check      only the cycles (silent and status 0 when there are none)

Python 3 standard library only.
"""

from __future__ import annotations

import argparse
import difflib
import re
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def strip(text: str) -> str:
    """`text` with comments, string and char literals blanked out; newlines are kept, so line
    numbers stay right."""
    out = []
    i, n = 0, len(text)

    def blank(s: str) -> str:
        return "".join(c if c == "\n" else " " for c in s)

    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(blank(text[i:j]))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(blank(text[i:j]))
            i = j
        elif (m := re.compile(r'b?r(#*)"').match(text, i)) and (
            i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")
        ):
            end = '"' + m.group(1)
            j = text.find(end, m.end())
            j = n if j < 0 else j + len(end)
            out.append(blank(text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(blank(text[i : j + 1]))
            i = j + 1
        elif c == "'":
            # A char literal ('x', '\n', '\u{..}'), or a lifetime / label ('a), kept as is.
            m = re.compile(r"'(\\u\{[0-9A-Fa-f]*\}|\\.|[^\\'])'").match(text, i)
            if m:
                out.append(blank(m.group(0)))
                i = m.end()
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*|::|#\[|[{}();,\[\]]|\S")


def tokens(code: str):
    """(token, line) pairs."""
    line = 1
    pos = 0
    for m in TOKEN.finditer(code):
        line += code.count("\n", pos, m.start())
        pos = m.start()
        yield m.group(0), line


def module_path(rel: Path) -> list[str]:
    """The module path of a file under src/: src/a/b.rs -> [a, b], src/a/mod.rs -> [a]."""
    parts = list(rel.with_suffix("").parts)
    if parts[-1] == "mod":
        parts.pop()
    return parts


def group_heads(toks, k):
    """The first path segment of each item of the `{ ... }` group whose `{` is toks[k]:
    (segment, line) pairs, and the index after the closing brace."""
    heads = []
    depth = 0
    expect = True
    j = k
    while j < len(toks):
        t, line = toks[j]
        if t == "{":
            depth += 1
            if depth == 1:
                expect = True
        elif t == "}":
            depth -= 1
            if depth == 0:
                return heads, j + 1
        elif depth == 1 and t == ",":
            expect = True
        elif depth == 1 and expect:
            if IDENT.fullmatch(t):
                heads.append((t, line))
            expect = False
        j += 1
    return heads, j


def references(path: Path, rel: Path, modules: set[str]):
    """(target top-level module, line) for every path from this file into another top-level
    module."""
    toks = list(tokens(strip(path.read_text(encoding="utf-8"))))
    base = module_path(rel)
    # Stack of (brace depth at which the inline module's body opened, module name).
    inline: list[tuple[int, str]] = []
    depth = 0
    found = []
    i = 0
    pending_cfg_test = False
    while i < len(toks):
        t, line = toks[i]
        if t == "#[":
            # An attribute: note `#[cfg(test)]`, skip to its closing bracket.
            j, d = i + 1, 1
            while j < len(toks) and d:
                d += {"[": 1, "]": -1}.get(toks[j][0], 0)
                j += 1
            attr = "".join(x for x, _ in toks[i + 1 : j - 1])
            if attr == "cfg(test)":
                pending_cfg_test = True
            i = j
            continue
        if t == "mod" and i + 2 < len(toks) and IDENT.fullmatch(toks[i + 1][0]):
            name, nxt = toks[i + 1][0], toks[i + 2][0]
            if nxt == "{":
                if pending_cfg_test:
                    # Skip the test module's body.
                    j, d = i + 3, 1
                    while j < len(toks) and d:
                        d += {"{": 1, "}": -1}.get(toks[j][0], 0)
                        j += 1
                    i = j
                    pending_cfg_test = False
                    continue
                depth += 1
                inline.append((depth, name))
                i += 3
                continue
        if t not in ("#[",) and t != "pub" and t != "(" and t != ")" and t != "crate":
            if t not in ("mod",):
                pending_cfg_test = pending_cfg_test and t in ("pub",)
        if t == "{":
            depth += 1
        elif t == "}":
            if inline and inline[-1][0] == depth:
                inline.pop()
            depth -= 1
        elif t in ("crate", "super") and i + 1 < len(toks) and toks[i + 1][0] == "::":
            if i > 0 and toks[i - 1][0] == "::":
                i += 1
                continue  # `super::super::...`: handled with the first `super`
            if t == "crate":
                current: list[str] = []
                j = i + 2
            else:
                current = base + [name for _, name in inline]
                j = i
                while (
                    j + 1 < len(toks) and toks[j][0] == "super" and toks[j + 1][0] == "::"
                ):
                    current = current[:-1]
                    j += 2
            if current:
                # Still inside a top-level module: `current[0]` is the target.
                found.append((current[0], line))
            elif j < len(toks):
                nt = toks[j][0]
                if nt == "{":
                    heads, _ = group_heads(toks, j)
                    found.extend((h, ln) for h, ln in heads if h in modules)
                elif nt in modules:
                    found.append((nt, line))
            i = j
            continue
        i += 1
    return found


def build_graph(root: Path):
    src = root / "src"
    modules = set()
    for p in src.iterdir():
        if p.is_dir() and ((p / "mod.rs").exists() or any(p.glob("*.rs"))):
            modules.add(p.name)
        elif p.suffix == ".rs" and p.stem not in ("lib", "main"):
            modules.add(p.stem)
    # edges[(a, b)] = [(file, line), ...]
    edges: dict[tuple[str, str], list[tuple[str, int]]] = defaultdict(list)
    for path in sorted(src.rglob("*.rs")):
        rel = path.relative_to(src)
        top = rel.parts[0].removesuffix(".rs")
        if top not in modules:
            continue  # lib.rs, main.rs
        for target, line in references(path, rel, modules):
            if target != top and target in modules:
                edges[(top, target)].append((f"src/{rel.as_posix()}", line))
    return sorted(modules), edges


def sccs(nodes, adj):
    """Tarjan's strongly connected components."""
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(adj[v]):
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
            out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in nodes:
        if v not in index:
            visit(v)
    return out


def elementary_cycles(comp, adj, limit=200):
    """Simple cycles inside one component, each starting at its smallest module (at most
    `limit` of them)."""
    members = set(comp)
    cycles = []
    for start in comp:
        allowed = {m for m in members if m >= start}
        path = [start]

        def walk(v):
            for w in sorted(adj[v] & allowed):
                if len(cycles) >= limit:
                    return
                if w == start:
                    cycles.append(path + [start])
                elif w not in path:
                    path.append(w)
                    walk(w)
                    path.pop()

        walk(start)
    return cycles


def largest_files(root: Path, count: int):
    files = []
    for folder, pattern in (("src", "*.rs"), ("cuda", "*")):
        for p in (root / folder).rglob(pattern):
            if p.is_file() and p.suffix in (".rs", ".cu", ".cuh", ".h", ".hpp", ".cpp"):
                with p.open(encoding="utf-8", errors="replace") as f:
                    files.append((sum(1 for _ in f), p.relative_to(root).as_posix()))
    files.sort(key=lambda x: (-x[0], x[1]))
    return files[:count]


def mermaid(modules, edges, cyclic):
    lines = ["```mermaid", "graph LR"]
    links = sorted(edges)
    for m in modules:
        lines.append(f"    {m}")
    red = []
    for k, (a, b) in enumerate(links):
        lines.append(f"    {a} -->|{len(edges[(a, b)])}| {b}")
        if (a, b) in cyclic:
            red.append(str(k))
    if red:
        lines.append(f"    linkStyle {','.join(red)} stroke:#d00,stroke-width:2px")
    lines.append("```")
    return "\n".join(lines)


def markdown(root, files, modules, edges, cyclic, report) -> str:
    """The Architecture at a glance block: the graph, the largest files and any cycle."""
    out = [
        "Imports between the top-level modules of `src/` (an arrow A → B: code of A names "
        "B; the label counts the references; red arrows are in an import cycle). "
        "Generated by `make graph` (`scripts/module_graph.py`); `make lint` fails on a cycle.",
        "",
        mermaid(modules, edges, cyclic),
        "",
        "The largest source files:",
        "",
        "| lines | file |",
        "|------:|------|",
    ]
    out += [f"| {count} | `{name}` |" for count, name in largest_files(root, files)]
    if report:
        out += ["", "Import cycles (`make lint` fails on these):", "", "```", *report, "```"]
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--markdown", action="store_true", help="the Architecture at a glance block")
    mode.add_argument("--check", action="store_true", help="only report import cycles")
    mode.add_argument(
        "--update",
        type=Path,
        metavar="FILE",
        help="write the block between FILE's module-graph markers (docs/design.md)",
    )
    mode.add_argument(
        "--check-doc",
        type=Path,
        metavar="FILE",
        help="fail, with a diff, when the block between FILE's markers is not current "
        "(`make lint`; `make graph` rewrites it)",
    )
    ap.add_argument("--files", type=int, default=12, help="how many of the largest files to list")
    ap.add_argument("--root", type=Path, default=ROOT, help="the repository (default: this one)")
    args = ap.parse_args()

    modules, edges = build_graph(args.root)
    adj = defaultdict(set)
    for a, b in edges:
        adj[a].add(b)
    components = [c for c in sccs(modules, adj) if len(c) > 1]
    cyclic = {(a, b) for c in components for a in c for b in c if (a, b) in edges}

    report = []
    for comp in components:
        report.append(f"import cycle between top-level modules: {', '.join(comp)}")
        for a, b in sorted(e for e in edges if e in cyclic and e[0] in comp):
            sites = edges[(a, b)]
            shown = ", ".join(f"{f}:{n}" for f, n in sites[:6])
            more = f" (+{len(sites) - 6} more)" if len(sites) > 6 else ""
            report.append(f"  {a} -> {b}: {shown}{more}")
        for cyc in elementary_cycles(comp, adj):
            report.append(f"  cycle: {' -> '.join(cyc)}")

    if args.check:
        if report:
            print("\n".join(report), file=sys.stderr)
        return 1 if report else 0

    if args.markdown or args.update or args.check_doc:
        text = markdown(args.root, args.files, modules, edges, cyclic, report)
        if args.check_doc:
            doc = args.check_doc.read_text()
            begin, end = "<!-- module-graph:begin -->", "<!-- module-graph:end -->"
            if begin not in doc or end not in doc:
                print(f"{args.check_doc}: no {begin} … {end} markers", file=sys.stderr)
                return 2
            current = doc.split(begin, 1)[1].split(end, 1)[0].strip("\n")
            if current != text.strip("\n"):
                diff = difflib.unified_diff(
                    current.splitlines(),
                    text.strip("\n").splitlines(),
                    f"{args.check_doc} (as written)",
                    "scripts/module_graph.py (now)",
                    lineterm="",
                )
                print("\n".join(diff), file=sys.stderr)
                print(
                    f"{args.check_doc}: the module graph block is stale; `make graph` rewrites it",
                    file=sys.stderr,
                )
                return 1
            return 1 if report else 0
        if args.markdown:
            print("### Architecture at a glance")
            print()
            print(text)
        else:
            doc = args.update.read_text()
            begin, end = "<!-- module-graph:begin -->", "<!-- module-graph:end -->"
            if begin not in doc or end not in doc:
                print(f"{args.update}: no {begin} … {end} markers", file=sys.stderr)
                return 2
            head, rest = doc.split(begin, 1)
            _, tail = rest.split(end, 1)
            args.update.write_text(f"{head}{begin}\n{text}\n{end}{tail}")
            print(f"{args.update}: the module graph and file sizes are current")
    else:
        print(mermaid(modules, edges, cyclic))
        print()
        print("largest source files (lines):")
        for count, name in largest_files(args.root, args.files):
            print(f"  {count:6d}  {name}")
        print()
        print("\n".join(report) if report else "no import cycles between top-level modules")
    return 1 if report else 0


if __name__ == "__main__":
    sys.exit(main())
