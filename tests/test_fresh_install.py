"""The README's first command on a fresh clone in a fresh virtual environment.

Slow (it installs numpy, scipy, sympy, fmpy, pythonfmu and matplotlib), so it
is marked ``install`` and left out of the default run; ``.ci/run`` runs it
(``python -m pytest -m install``).
"""
import os
import re
import shutil
import subprocess
import sys
import time
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def readme_commands():
    """The lines of the README's first ```bash block."""
    block = re.search(r"^```bash\n(.*?)^```", (ROOT / "README.md").read_text(), re.S | re.M)
    return [line for line in block.group(1).splitlines() if line.strip()]


def test_readme_starts_with_the_two_commands():
    assert readme_commands() == [
        'python -m pip install -e ".[fmu]" && python examples/main_job.py',
        'python -m pip install -e ".[test]" && python -m pytest',
    ]


@pytest.mark.install
def test_first_command_on_a_fresh_clone(tmp_path):
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    clone = tmp_path / "lsc"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True, timeout=300)
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    bindir = env_dir / ("Scripts" if sys.platform == "win32" else "bin")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}
    env.update(VIRTUAL_ENV=str(env_dir), PATH=os.pathsep.join([str(bindir), env.get("PATH", "")]), MPLBACKEND="Agg")
    command = readme_commands()[0]
    t0 = time.perf_counter()
    out = subprocess.run(["bash", "-c", command], cwd=clone, env=env, capture_output=True, text=True, timeout=3600)
    elapsed = time.perf_counter() - t0
    print(f"README's first command on a fresh clone: {elapsed:.0f} s")
    assert out.returncode == 0, (out.stdout[-3000:], out.stderr[-3000:])
    assert (clone / "out" / "main_job.png").stat().st_size > 10_000
    assert "validate_fmu: no problems" in out.stdout
    # the clone's own code ran, not the developer's checkout
    where = subprocess.run([str(bindir / "python"), "-c", "import lsc; print(lsc.__file__)"], env=env, cwd=env_dir,
                           capture_output=True, text=True, check=True).stdout
    assert Path(where.strip()).is_relative_to(clone), where
