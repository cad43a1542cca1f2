"""The README's picture shows what a run shows.

``python examples/main_job.py --docs`` writes docs/_generated/main_job.png and, beside it,
main_job.json: the numbers the picture draws (the constraint residual of each run at t = 0, 1,
..., 10, the errors against the exact solution). The PNG carries the SHA-256 of that JSON, so
the picture and its numbers come from one run; a fresh run of the main job must give the same
numbers.
"""
import hashlib
import json
import math
import os
import subprocess
import sys

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("matplotlib")

from tests.support import ROOT  # noqa: E402
GENERATED = ROOT / "docs" / "_generated"
# Below this the values are the integrator's rounding noise: they must stay below it, not agree.
FLOOR = 1e-9


def _png_text(path):
    from PIL import Image

    with Image.open(path) as image:
        return dict(image.text)


def test_the_readme_picture_is_drawn_from_the_numbers_beside_it():
    numbers = (GENERATED / "main_job.json").read_bytes()
    text = _png_text(GENERATED / "main_job.png")
    assert text.get("numbers") == "main_job.json sha256 " + hashlib.sha256(numbers).hexdigest(), (
        "docs/_generated/main_job.png was not drawn with main_job.json beside it: run python examples/main_job.py --docs")
    assert "docs/_generated/main_job.png" in (ROOT / "README.md").read_text()


def _same(shown, run, where):
    if isinstance(shown, dict):
        assert set(shown) == set(run), where
        for key in shown:
            _same(shown[key], run[key], f"{where}.{key}")
    elif isinstance(shown, list):
        assert len(shown) == len(run), where
        for i, (a, b) in enumerate(zip(shown, run)):
            _same(a, b, f"{where}[{i}]")
    elif isinstance(shown, float) and isinstance(run, float):
        if max(abs(shown), abs(run)) < FLOOR:
            return
        assert math.isclose(shown, run, rel_tol=0.05), f"{where}: the picture shows {shown:.3e}, a run gives {run:.3e}"
    else:
        assert shown == run, where


def test_the_readme_picture_shows_what_a_run_shows(tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "examples" / "main_job.py"), "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=900, cwd=tmp_path,
                         env={**os.environ, "MPLBACKEND": "Agg"})
    assert run.returncode == 0, run.stderr[-3000:]
    shown = json.loads((GENERATED / "main_job.json").read_text())
    fresh = json.loads((tmp_path / "main_job.json").read_text())
    _same(shown, fresh, "main_job.json")
    assert (tmp_path / "main_job.png").stat().st_size > 10_000
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix in (".png", ".json")) == ["main_job.json",
                                                                                             "main_job.png"]
