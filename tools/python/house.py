#!/usr/bin/env python3
"""The library's house rules, checked from its sources:

- no file of `src/`, of the Python extension (`python/src`) or of the Python package over 1,000
  lines;
- the layers of docs/ARCHITECTURE.md ("## Layers"): every top-level module of `src/` in one
  layer, and no import from a module to one in a higher layer;
- no import circle between top-level modules, nor between library files (a module and its own
  descendants aside);
- the crate root public only as its facade: `src/lib.rs` declares `said` and `internal`, and
  `src/internal.rs` declares every other top-level module (hidden from the docs);
- `unsafe` code only in the files docs/ARCHITECTURE.md names ("`unsafe` in few places"), and
  printing or exiting only in `interrupt.rs` (the signal handler the same page describes).

`python3 tools/python/house.py` from the repository root prints each breach (for a circle, the
files on it and what each imports from the others) and exits 1 when there is any. Imports are
read as text: every `crate::a::b` and `super::…` path outside comments and test modules, each
resolved to the deepest module file it names; `src/cli` (the binary) is left out. A path through
a parent's re-export counts as an import of the parent.
"""

import os
import re
import sys

ROOT = "src"
MAX_LINES = 1000
ARCHITECTURE = "docs/ARCHITECTURE.md"
# Python sources under the same size rule as the library's.
PYTHON = ["python/src", "python/python/rigidcells", "blender/rigidcells_blender"]
# The one library file that prints and exits: the signal handler.
PRINTS = {"src/interrupt.rs"}
# The modules the crate root declares itself: the facade's (the rest are `internal`'s).
FACADE = {"said", "internal"}


def modules():
    """Module path (a tuple) -> file, for every library file."""
    out = {}
    for folder, _, files in os.walk(ROOT):
        for name in files:
            if not name.endswith(".rs") or name == "main.rs":
                continue
            path = os.path.join(folder, name)
            parts = os.path.relpath(path, ROOT)[:-3].split(os.sep)
            if parts[-1] in ("mod", "lib"):
                parts = parts[:-1]
            if parts and parts[0] == "cli":
                continue
            # Declares the modules behind the facade, holding no code: see `facade_breaches`.
            if parts == ["internal"]:
                continue
            out[tuple(parts)] = path
    return out


def imports(mods):
    """Module -> the modules it imports, parents and descendants left out."""
    def resolve(path):
        for k in range(len(path), 0, -1):
            if tuple(path[:k]) in mods:
                return tuple(path[:k])
        return None

    edges = {}
    for m, path in mods.items():
        text = open(path, encoding="utf-8").read()
        text = re.sub(r"//[^\n]*", "", text)
        text = re.sub(r"(?s)#\[cfg\(test\)\]\s*mod tests.*", "", text)
        found = set()
        for hit in re.finditer(r"crate::((?:[a-z_0-9]+::)*[A-Za-z_0-9]+)", text):
            found.add(resolve(hit.group(1).split("::")))
        for hit in re.finditer(r"\b((?:super::)+)((?:[a-z_0-9]+::)*[A-Za-z_0-9]*)", text):
            base = list(m)
            for _ in range(hit.group(1).count("super::")):
                base = base[:-1]
            rest = [p for p in hit.group(2).split("::") if p]
            found.add(resolve(base + rest) if base + rest else ())
        edges[m] = {
            t for t in found
            if t is not None and t != m and t[: len(m)] != m and m[: len(t)] != t
        }
    return edges


def circles(edges):
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
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
            if len(comp) > 1:
                out.append(comp)

    for v in edges:
        if v not in index:
            visit(v)
    return out


def layers():
    """Top-level module -> its layer's number, from ARCHITECTURE.md's "## Layers" list."""
    text = open(ARCHITECTURE, encoding="utf-8").read()
    section = text.split("\n## Layers\n", 1)[1].split("\n## ", 1)[0]
    out = {}
    for line in section.splitlines():
        item = re.match(r"(\d+)\. [^`]*(.*)", line)
        if item:
            for name in re.findall(r"`([a-z_]+)`", item.group(2)):
                out[name] = int(item.group(1))
    return out


def layer_breaches(mods, edges):
    """Lines naming each module in no layer and each import upward across layers."""
    rank = layers()
    out = [f"{top}: in no layer of {ARCHITECTURE}" for top in sorted({m[0] for m in mods if m})
           if top not in rank]
    for a in sorted(edges):
        for b in sorted(edges[a]):
            if a and b and a[0] != b[0] and rank.get(b[0], 0) > rank.get(a[0], 0):
                out.append(f"{'::'.join(a)} (layer {rank.get(a[0])}) imports {'::'.join(b)} "
                           f"(layer {rank[b[0]]})")
    return out


def code(path):
    """A Rust file's text without comments and without its test module."""
    text = open(path, encoding="utf-8").read()
    text = re.sub(r"//[^\n]*", "", text)
    return re.sub(r"(?s)#\[cfg\(test\)\]\s*mod tests.*", "", text)


def site_breaches(mods):
    """Lines naming each file whose `unsafe` code or printing the docs do not list."""
    text = open(ARCHITECTURE, encoding="utf-8").read()
    paragraph = text.split("**`unsafe` in few places.**", 1)[1].split("\n\n", 1)[0]
    listed = {os.path.join(ROOT, p) for p in re.findall(r"`([a-z_/]+\.rs)`", paragraph)}
    found, prints = set(), set()
    for path in mods.values():
        body = code(path)
        if re.search(r"\bunsafe\s*(\{|fn\b|impl\b)", body):
            found.add(path)
        if re.search(r"\b(e?print(ln)?!|process::exit|std::process::abort)", body):
            prints.add(path)
    out = [f"{p}: `unsafe` code, not listed in {ARCHITECTURE}" for p in sorted(found - listed)]
    out += [f"{p}: listed in {ARCHITECTURE} as holding `unsafe` code, and has none"
            for p in sorted(listed - found)]
    out += [f"{p}: prints or exits (only the signal handler in interrupt.rs may)"
            for p in sorted(prints - PRINTS)]
    return out


def top_circles(edges):
    """Circles between top-level modules."""
    top = {}
    for a, bs in edges.items():
        for b in bs:
            if a and b and a[0] != b[0]:
                top.setdefault((a[0],), set()).add((b[0],))
    for m in list(top.values()):
        for b in m:
            top.setdefault(b, set())
    return circles(top)


def facade_breaches(mods):
    """Top-level modules declared where they should not be: the root declares `said` and
    `internal`; `internal.rs` every other one, by `#[path]` to its own file."""
    declared = lambda path: re.findall(r"(?m)^\s*pub(?:\([a-z]+\))? mod ([a-z_0-9]+);", code(path))
    public = set(declared(os.path.join(ROOT, "lib.rs")))
    hidden = set(declared(os.path.join(ROOT, "internal.rs")))
    tops = {m[0] for m in mods if m}
    out = [f"src/lib.rs declares {m}, which is not part of the facade: declare it in src/internal.rs"
           for m in sorted(public - FACADE)]
    out += [f"src/{m}: a top-level module that src/internal.rs does not declare"
            for m in sorted(tops - hidden - FACADE)]
    return out


def python_files():
    for folder in PYTHON:
        for base, _, files in os.walk(folder):
            for name in sorted(files):
                if name.endswith((".rs", ".py")):
                    yield os.path.join(base, name)


def main():
    mods = modules()
    long = []
    for path in sorted(mods.values()) + sorted(python_files()):
        n = sum(1 for _ in open(path, encoding="utf-8"))
        if n > MAX_LINES:
            long.append((path, n))
    for path, n in long:
        print(f"{path}: {n} lines (at most {MAX_LINES})")
    edges = imports(mods)
    found = circles(edges)
    for comp in found:
        names = sorted("::".join(c) for c in comp)
        print("import circle:", ", ".join(names))
        for a in comp:
            inner = sorted("::".join(b) for b in edges[a] if b in comp)
            print(f"  {'::'.join(a)} imports {', '.join(inner)}")
    tops = top_circles(edges)
    for comp in tops:
        print("module circle:", ", ".join(sorted(c[0] for c in comp)))
    breaches = layer_breaches(mods, edges) + site_breaches(mods) + facade_breaches(mods)
    for line in breaches:
        print(line)
    print(
        f"{len(mods)} library files, {len(long)} files over {MAX_LINES} lines, "
        f"{len(found)} file circles, {len(tops)} module circles, {len(breaches)} other breaches"
    )
    return 1 if long or found or tops or breaches else 0


if __name__ == "__main__":
    sys.exit(main())
