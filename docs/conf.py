"""Sphinx configuration: Markdown pages (MyST), numpydoc docstrings, API from autodoc."""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

project = "lsc"
author = "the lsc developers"
extensions = [
    "myst_parser",
    "numpydoc",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "_generated/*.md"]  # generated tables are included by benchmarks.md
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
autosummary_generate = False
html_theme = "alabaster"
html_static_path = []


def _include_generated(app, docname, source):
    """The benchmarks page lists every table and figure the benchmark scripts wrote."""
    if docname != "reference/benchmarks":
        return
    generated = HERE / "_generated"
    parts = [source[0]]
    for table in sorted(generated.glob("*.md")):
        parts.append(f"\n\n```{{include}} ../_generated/{table.name}\n```\n")
    for figure in sorted(generated.glob("*.png")):
        if figure.name == "main_job.png":  # the README's picture, not a benchmark
            continue
        parts.append(f"\n\n```{{figure}} ../_generated/{figure.name}\n:width: 80%\n\n`{figure.name}`\n```\n")
    source[0] = "".join(parts)


def setup(app):
    app.connect("source-read", _include_generated)
