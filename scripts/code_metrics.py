"""Module sizes and the longest functions of a source tree (the architecture's before/after figures).

python scripts/code_metrics.py [ROOT] [--top N]: lines per module (code lines, no blank or
comment-only lines) and the N longest functions/methods, from the ast.
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path


def code_lines(text: str) -> int:
    return sum(1 for line in text.splitlines() if line.strip() and not line.strip().startswith("#"))


def functions(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text())
    out = []

    def walk(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                where = f"{path}:{child.lineno} {prefix}{child.name}"
                out.append((child.end_lineno - child.lineno + 1, where))
                walk(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                walk(child, f"{prefix}{child.name}.")

    walk(tree, "")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("roots", nargs="*", default=["stream_viz", "plugins"])
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args()
    files = sorted(p for r in args.roots for p in Path(r).rglob("*.py")
                   if not any(part.startswith(".") or part == "out" for part in p.parts))
    sizes = sorted(((len(p.read_text().splitlines()), code_lines(p.read_text()), str(p)) for p in files),
                   reverse=True)
    total = sum(s[0] for s in sizes)
    print(f"{len(files)} modules, {total} lines; largest (lines, code lines):")
    for n, c, p in sizes[: args.top]:
        print(f"  {n:5d} {c:5d}  {p}")
    funcs = sorted((f for p in files for f in functions(p)), reverse=True)
    print(f"longest functions (of {len(funcs)}; lines):")
    for n, name in funcs[: args.top]:
        print(f"  {n:4d}  {name}")
    over = sum(1 for n, _ in funcs if n > 50)
    print(f"functions over 50 lines: {over}")


if __name__ == "__main__":
    main()
