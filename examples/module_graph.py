"""The module import graph of lsc and fmu_build, read from the code (ast, nothing imported).

For every module: its lines, its longest function (lines from ``def`` to its
last line, docstring excluded), its longest class (likewise from ``class``) and
the project modules it imports, at module
level or inside a function (marked ``*``: imported when called). Cycles
between modules are listed (package ``__init__`` files are left out of the
cycle search: importing a package from inside a function of its own
submodule runs after the package is loaded). A picture of the graph (one
column per import depth) is drawn with matplotlib when it is installed.

Run:  python examples/module_graph.py [--name NAME] [--docs]

Writes ``out/module_graph_NAME.md`` (and ``.png``); with ``--docs`` the
Markdown goes to ``docs/_generated/module_graph_NAME.md`` instead and the
picture stays under ``out/`` (no tracked file changes without ``--docs``).
"""

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("lsc", "fmu_build")


def modules(root=ROOT, packages=PACKAGES):
    """``{dotted name: path}`` of every Python module of `packages` under `root`."""
    found = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path
    return found


def _resolve(name, known):
    """The longest prefix of the dotted `name` that is a known module, or None."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        candidate = ".".join(parts[:i])
        if candidate in known:
            return candidate
    return None


def _imports(name, path, known):
    """``{imported module: lazy}``: lazy when every import of it sits inside a function."""
    tree = ast.parse(path.read_text())
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rpartition(".")[0]
    top_level = {id(node) for node in tree.body}
    top_level |= {id(n) for node in tree.body if isinstance(node, (ast.Try, ast.If)) for n in ast.walk(node)}
    found = {}

    def add(target, node):
        if target and target != name:
            found[target] = found.get(target, True) and id(node) not in top_level

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(_resolve(alias.name, known), node)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:  # `from pkg import submodule` imports the submodule
                add(_resolve(f"{source}.{alias.name}", known), node)
    return found


def _functions(tree):
    """``(qualified name, lines)`` of every function, docstring lines not counted."""
    out = []

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = child.end_lineno - child.lineno + 1
                doc = child.body[0] if child.body else None
                if isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant) and isinstance(doc.value.value, str):
                    lines -= doc.end_lineno - doc.lineno + 1
                out.append((prefix + child.name, lines))
                visit(child, prefix + child.name + ".")
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def _classes(tree):
    """``(qualified name, lines)`` of every class, docstring lines not counted."""
    out = []

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                lines = child.end_lineno - child.lineno + 1
                doc = child.body[0] if child.body else None
                if isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant) and isinstance(doc.value.value, str):
                    lines -= doc.end_lineno - doc.lineno + 1
                out.append((prefix + child.name, lines))
                visit(child, prefix + child.name + ".")
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                visit(child, prefix + child.name + ".")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def graph(root=ROOT, packages=PACKAGES):
    """One dict per module: name, lines, functions and classes, the longest of each, imports ``{module: lazy}``."""
    known = modules(root, packages)
    rows = []
    for name, path in known.items():
        text = path.read_text()
        tree = ast.parse(text)
        functions, classes = _functions(tree), _classes(tree)
        longest = max(functions, key=lambda f: f[1], default=("", 0))
        largest = max(classes, key=lambda c: c[1], default=("", 0))
        rows.append({"module": name, "lines": len(text.splitlines()), "longest": longest, "functions": functions,
                     "largest": largest, "classes": classes,
                     "imports": _imports(name, path, known), "package": path.name == "__init__.py"})
    return rows


def cycles(rows):
    """The strongly connected components with more than one module, packages left out."""
    from fmu_build.cosim._graph import _strongly_connected  # the master's Tarjan, reused

    nodes = {r["module"] for r in rows if not r["package"]}
    edges = {r["module"]: sorted(set(r["imports"]) & nodes) for r in rows if r["module"] in nodes}
    return sorted(sorted(scc) for scc in _strongly_connected(edges) if len(scc) > 1)


def markdown(rows, title):
    """The table, a summary and the cycles as Markdown text."""
    found = cycles(rows)
    lines = [f"## Module graph: {title}", "",
             "`python examples/module_graph.py`: lines per module, its longest function and its largest class "
             "(docstrings not counted) and the project modules it imports (`*`: only inside a function).", "",
             "| module | lines | longest function | largest class | imports |", "|---|---:|---|---|---|"]
    for r in rows:
        name, length = r["longest"]
        cname, clength = r["largest"]
        imports = ", ".join(f"{m}{'*' if lazy else ''}" for m, lazy in sorted(r["imports"].items()))
        lines.append(f"| `{r['module']}` | {r['lines']} | {f'`{name}` ({length})' if name else ''} | "
                     f"{f'`{cname}` ({clength})' if cname else ''} | {imports} |")
    biggest = sorted(rows, key=lambda r: -r["lines"])[:5]
    longest = sorted(rows, key=lambda r: -r["longest"][1])[:5]
    largest = sorted(rows, key=lambda r: -r["largest"][1])[:5]
    lines += ["", f"{len(rows)} modules, {sum(r['lines'] for r in rows)} lines; "
              f"over 600 lines: {sum(r['lines'] > 600 for r in rows)}; "
              f"functions over 80 lines: {sum(n > 80 for r in rows for _, n in r['functions'])}; "
              f"classes over 300 lines: {sum(n > 300 for r in rows for _, n in r['classes'])}.", "",
              "Largest modules: " + ", ".join(f"`{r['module']}` {r['lines']}" for r in biggest) + ".", "",
              "Longest functions: " + ", ".join(f"`{r['module']}.{r['longest'][0]}` {r['longest'][1]}" for r in longest) + ".",
              "", "Largest classes: " + ", ".join(f"`{r['module']}.{r['largest'][0]}` {r['largest'][1]}" for r in largest) + ".",
              "", "Import cycles: " + ("; ".join(" <-> ".join(c) for c in found) if found else "none") + "."]
    return "\n".join(lines) + "\n"


def _layers(rows):
    """Import depth of each module (0: imports no project module), cycles cut."""
    edges = {r["module"]: set(r["imports"]) for r in rows}
    depth = {}

    def visit(v, seen):
        if v in depth:
            return depth[v]
        if v in seen:
            return 0
        d = 1 + max((visit(w, seen | {v}) for w in edges.get(v, ())), default=-1)
        depth[v] = d
        return d

    for v in edges:
        visit(v, frozenset())
    return depth


def _collapsed(rows, keep="fmu_build"):
    """The rows with every module outside `keep` folded into its top-level package (one node: ``lsc``)."""
    def node(name):
        return name if name.split(".")[0] == keep else name.split(".")[0]

    out = {}
    for r in rows:
        row = out.setdefault(node(r["module"]), {"module": node(r["module"]), "lines": 0, "imports": {},
                                                 "package": r["package"] and node(r["module"]) == r["module"]})
        row["lines"] += r["lines"]
        for target, lazy in r["imports"].items():
            if node(target) != row["module"]:
                row["imports"][node(target)] = row["imports"].get(node(target), True) and lazy
    return list(out.values())


def picture(rows, path, title):
    """Draw the fmu_build graph (lsc as one node) with matplotlib, one column per import depth.

    Returns False when matplotlib is missing.
    """
    cyclic = {m for c in cycles(rows) for m in c}
    rows = _collapsed(rows)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    depth = _layers(rows)
    columns = {}
    for r in sorted(rows, key=lambda r: r["module"]):
        columns.setdefault(depth[r["module"]], []).append(r["module"])
    position = {m: (d, -i) for d, ms in columns.items() for i, m in enumerate(ms)}
    tall = max(len(ms) for ms in columns.values())
    fig, ax = plt.subplots(figsize=(3.2 * len(columns) + 1, 0.42 * tall + 1))
    for r in rows:
        x0, y0 = position[r["module"]]
        for target, lazy in r["imports"].items():
            x1, y1 = position[target]
            ax.annotate("", xy=(x1 + 0.45, y1), xytext=(x0 - 0.05, y0),
                        arrowprops=dict(arrowstyle="->", lw=0.5, alpha=0.35, ls=":" if lazy else "-",
                                        color="red" if {r["module"], target} <= cyclic else "gray"))
    for r in rows:
        x, y = position[r["module"]]
        color = "red" if r["module"] in cyclic else ("orange" if r["lines"] > 600 else "black")
        ax.text(x, y, f"{r['module']} ({r['lines']})", fontsize=7, va="center", color=color,
                bbox=dict(boxstyle="round", fc="white", ec="lightgray", lw=0.5))
    ax.set_xlim(-0.3, len(columns) * 1.0 + 0.3)
    ax.set_ylim(-tall, 1)
    ax.axis("off")
    ax.set_title(f"fmu_build, {title}: import depth left to right (red: in a cycle, orange: over 600 lines, dotted: lazy)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--name", default="current", help="suffix of the files written (e.g. before, after)")
    parser.add_argument("--docs", action="store_true", help="write the Markdown to docs/_generated/")
    args = parser.parse_args(argv)
    rows = graph()
    text = markdown(rows, args.name)
    out = ROOT / "out"
    out.mkdir(exist_ok=True)
    target = (ROOT / "docs" / "_generated" if args.docs else out) / f"module_graph_{args.name}.md"
    target.write_text(text)
    drawn = picture(rows, out / f"module_graph_{args.name}.png", args.name)
    print(text)
    print(f"written: {target}" + (f", {out / f'module_graph_{args.name}.png'}" if drawn else " (no matplotlib: no picture)"),
          file=sys.stderr)


if __name__ == "__main__":
    main()
