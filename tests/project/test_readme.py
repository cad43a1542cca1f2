"""Every ```python block of the README and of the docs pages runs, and prints what the page says.

A block runs in a fresh subprocess whose working folder holds a copy of
``examples/`` (the snippets use paths relative to the repository). When a
```text block follows under "prints", the output must match it exactly, line by
line and character by character, with one stated tolerance: a number below
``ROUNDING`` (1e-9) in magnitude on both sides only has to stay below it, since
such values are rounding-level residuals whose digits depend on the BLAS and
the CPU. Blocks not meant to run are written as ```text or ```bash.
"""
import os
import re
import shutil
import subprocess
import sys

import pytest

from tests.support import ROOT
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
PAGES = [p for p in PAGES if "_build" not in p.parts and "_generated" not in p.parts]
BLOCK = re.compile(r"^```python\n(.*?)^```\n(?:\s*prints\s*\n+```text\n(.*?)^```)?", re.S | re.M)
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def snippets():
    for page in PAGES:
        for i, m in enumerate(BLOCK.finditer(page.read_text())):
            yield pytest.param(m.group(1), m.group(2), id=f"{page.relative_to(ROOT)}-{i}")


ROUNDING = 1e-9


def same_output(found, expected):
    """The printed text equals the page's, apart from numbers below ROUNDING on both sides."""
    f_lines, e_lines = found.strip().splitlines(), expected.strip().splitlines()
    if len(f_lines) != len(e_lines):
        return False
    for fl, el in zip(f_lines, e_lines):
        if NUMBER.sub("#", fl.rstrip()) != NUMBER.sub("#", el.rstrip()):
            return False
        for a, b in zip(NUMBER.findall(fl), NUMBER.findall(el)):
            if a != b and not max(abs(float(a)), abs(float(b))) < ROUNDING:
                return False
    return True


def test_same_output_is_exact_above_rounding_level():
    assert same_output("err: 4.8e-07, u = -0.9636\n", "err: 4.8e-07, u = -0.9636")
    assert not same_output("err: 4.8e-07", "err: 4.7e-07")  # a wrong digit fails
    assert not same_output("u = -0.9636", "u = -0.9637")
    assert not same_output("u = -0.9636", "u  = -0.9636")  # the words and spacing too
    assert same_output("residual 2.0e-12", "residual 3.1e-13")  # both at rounding level
    assert not same_output("residual 2.0e-08", "residual 3.1e-13")


def test_there_are_snippets():
    ids = [p.id for p in snippets()]
    assert any(i.startswith("README.md") for i in ids) and any(i.startswith("docs/guide") for i in ids), ids


@pytest.mark.parametrize("code, expected", snippets())
def test_snippet_runs(code, expected, tmp_path):
    shutil.copytree(ROOT / "examples", tmp_path / "examples", ignore=shutil.ignore_patterns("__pycache__"))
    env = {**os.environ, "MPLBACKEND": "Agg"}
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip(), "a snippet must print its result"
    if expected is not None:
        assert same_output(out.stdout, expected), f"printed:\n{out.stdout}\nthe page says:\n{expected}"


def test_spec_reference_examples_form_a_valid_spec(tmp_path):
    """The ```toml blocks of the spec reference, put together, are one spec that builds and validates."""
    pytest.importorskip("pythonfmu")
    validation = pytest.importorskip("fmpy.validation")
    from fmu_build import build_fmu, load_spec

    blocks = re.findall(r"^```toml\n(.*?)^```", (ROOT / "docs" / "guide" / "spec.md").read_text(), re.S | re.M)
    assert len(blocks) == 8
    spec = tmp_path / "spec.toml"
    spec.write_text("\n".join(blocks))
    parsed = load_spec(spec)
    assert [s["name"] for s in parsed.states] == ["y", "v", "u"]
    assert [p["name"] for p in parsed.parameters if p["tunable"]] == ["c"]
    assert (parsed.method, parsed.lam) == ("alternative", 5.0)
    assert validation.validate_fmu(str(build_fmu(spec, tmp_path))) == []
