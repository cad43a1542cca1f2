"""The documentation builds with warnings as errors (sphinx-build -W)."""
import re
import subprocess
import sys

import pytest

from tests.support import ROOT

pytest.importorskip("sphinx", reason="the docs build needs the `test` or `docs` extra (sphinx)")
pytest.importorskip("numpydoc")
pytest.importorskip("myst_parser")


def test_docs_build_without_warnings(tmp_path):
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-E", "-b", "html", "-d",
           str(tmp_path / "doctrees"), str(ROOT / "docs"), str(tmp_path / "html")]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-5000:]
    api = (tmp_path / "html" / "reference" / "api.html").read_text()
    for name in ("lsc.complete", "lsc.solve_completion", "lsc.gallery.prescribed_path", "fmu_build.build_fmu",
                 "lsc.Completion.maps", "lsc.CompletionMaps", "lsc.Completion.lam_affine", "lsc.LamAffine",
                 "lsc.ExactPropagator", "lsc.chebyshev_coefficients"):
        assert f'id="{name}"' in api, name
    assert (tmp_path / "html" / "reference" / "benchmarks.html").exists()
    assert (tmp_path / "html" / "architecture.html").exists()


def test_readme_has_no_project_history():
    text = (ROOT / "README.md").read_text().lower()
    for word in ("session", "earlier version", "this issue", "issue #", "previously", "used to ", "re-run", "before the fix"):
        assert word not in text, word


def test_every_test_path_the_project_names_exists():
    """A test file, runner or C master named in the README, the docs, .ci/run or an example exists (the tests are
    laid out by package: a file moved without its mentions fails here)."""
    texts = [ROOT / "README.md", ROOT / ".ci" / "run", *(ROOT / "docs").rglob("*.md"), *(ROOT / "examples").rglob("*.py"),
             *(ROOT / "fmu_build").rglob("*.py")]
    named = {(path.relative_to(ROOT), ref) for path in texts
             for ref in re.findall(r"(?<![\w/])tests/[\w/]*\w\.(?:py|c)\b", path.read_text(encoding="utf-8"))}
    assert len(named) > 40
    missing = sorted(f"{path}: {ref}" for path, ref in named if not (ROOT / ref).is_file())
    assert not missing, missing
