#!/usr/bin/env python3
"""The structure rules of src/ (docs/architecture.md): no file-level import circle, no file
over 900 lines unless its module doc says in its first lines that it is one concept, and
no file of the project pointing outside the repository (`../shared`).

A file imports another when one of its paths names the other's module: `crate::a::b`,
`super::x`, `self::y`, and a bare path `child::item` or `use child::...` where `child` is
a module the file declares. Unit-test modules (`#[cfg(test)] mod tests`) are left out:
tests may use anything.

    tools/check/structure.py [ROOT]     exits 1 and lists what breaks a rule
"""
import os
import re
import sys
from pathlib import Path

MAX_LINES = 900
ROOT = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parents[2])


def module_of(src: Path, path: Path):
    parts = list(path.relative_to(src).with_suffix("").parts)
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    return tuple(parts)


def code_of(text: str) -> str:
    text = re.sub(r"#\[cfg\(test\)\]\s*(pub(\([^)]*\))?\s+)?mod tests\s*\{.*", "", text, flags=re.S)
    text = re.sub(r"//[^\n]*", "", text)
    return re.sub(r'"(\\.|[^"\\])*"', '""', text)


def edges(src: Path):
    files = sorted(src.rglob("*.rs"))
    modules = {module_of(src, f): f for f in files}

    def resolve(parts):
        parts = tuple(p for p in parts if p and p != "self")
        while parts:
            if parts in modules:
                return modules[parts]
            parts = parts[:-1]
        return None

    graph = {f: set() for f in files}
    for f in files:
        here = module_of(src, f)
        is_dir_module = f.name in ("mod.rs", "lib.rs", "main.rs")
        code = code_of(f.read_text(encoding="utf-8", errors="replace"))
        children = set(re.findall(r"^\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", code, flags=re.M))
        # `super` of a file is its parent module; of a mod.rs, the parent of its folder.
        parent = list(here[:-1])
        heads = {"crate": [], "super": parent, "self": list(here)}
        pattern = r"(?<![\w:])(crate|super|self|" + "|".join(map(re.escape, children or {"\0"})) + r")((?:::\w+)+)(::\{([^;]*?)\})?"
        for m in re.finditer(pattern, code):
            head = m.group(1)
            if head in heads:
                base = heads[head] + m.group(2).strip(":").split("::")
                if head == "super":
                    # super::super::x
                    rest = m.group(2).strip(":").split("::")
                    up = 0
                    while rest and rest[0] == "super":
                        rest, up = rest[1:], up + 1
                    base = parent[: len(parent) - up] + rest
            else:
                base = list(here) + [head] + m.group(2).strip(":").split("::")
            groups = [base]
            if m.group(4):
                groups = [base + g.strip().split("::") for g in re.split(r",(?![^{]*\})", m.group(4)) if g.strip()]
            for g in groups:
                target = resolve(g)
                if target and target != f:
                    graph[f].add(target)
        del is_dir_module
    return graph


def circles(graph):
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(100000)

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
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def problems(root: Path):
    src = root / "src"
    out = []
    for c in circles(edges(src)):
        out.append("import circle: " + " ".join(str(p.relative_to(root)) for p in c))
    for f in sorted(src.rglob("*.rs")):
        lines = f.read_text(encoding="utf-8", errors="replace").splitlines()
        if len(lines) > MAX_LINES and "one concept" not in "\n".join(lines[:15]).lower():
            out.append(f"{f.relative_to(root)}: {len(lines)} lines, and its module doc does not say it is one concept")
    tracked = os.popen(f"git -C '{root}' ls-files").read().split("\n")
    for name in tracked:
        p = root / name
        if not name or not p.is_file() or p.suffix in (".png", ".exr", ".bin", ".glb", ".jpg", ".webp"):
            continue
        if name == "tools/check/structure.py":
            continue
        try:
            if "../shared" in p.read_text(encoding="utf-8"):
                out.append(f"{name}: points at ../shared, which a clone does not have")
        except (UnicodeDecodeError, OSError):
            pass
    return out


if __name__ == "__main__":
    found = problems(ROOT)
    for line in found:
        print(line)
    print(f"{len(found)} problems" if found else "ok: no import circle, no oversized file, nothing points outside the repository")
    sys.exit(1 if found else 0)
