#!/usr/bin/env python3
"""The library's house rules, checked from its sources: no file of `src/` over 1,000 lines, and
no import circle between library files (a module and its own descendants aside).

`python3 tools/python/house.py` from the repository root prints each file over the bound and
each circle (the files on it and what each imports from the others) and exits 1 when there is
any. Imports are read as text: every `crate::a::b` and `super::…` path outside comments and
test modules, each resolved to the deepest module file it names; `src/cli` (the binary) is left
out. A path through a parent's re-export counts as an import of the parent.
"""

import os
import re
import sys

ROOT = "src"
MAX_LINES = 1000


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


def main():
    mods = modules()
    long = []
    for path in sorted(mods.values()):
        n = sum(1 for _ in open(path, encoding="utf-8"))
        if n > MAX_LINES:
            long.append((path, n))
    for path, n in long:
        print(f"{path}: {n} lines (at most {MAX_LINES})")
    found = circles(imports(mods))
    edges = imports(mods)
    for comp in found:
        names = sorted("::".join(c) for c in comp)
        print("import circle:", ", ".join(names))
        for a in comp:
            inner = sorted("::".join(b) for b in edges[a] if b in comp)
            print(f"  {'::'.join(a)} imports {', '.join(inner)}")
    print(f"{len(mods)} library files, {len(long)} over {MAX_LINES} lines, {len(found)} import circles")
    return 1 if long or found else 0


if __name__ == "__main__":
    sys.exit(main())
