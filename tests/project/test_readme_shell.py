"""Every shell line of the README, in order, on a fresh clone in a fresh virtual environment.

The clone is ``git clone`` of this checkout's HEAD; the virtual environment
starts empty (pip's download cache is reused). The lines of every ```bash block
run in one bash process, in the README's order, so ``eval "$(lsc-fmu env)"``
reaches the next line as it does for a reader; every ```python block runs where
it stands on the page, as ``python block.py`` from the clone's root
(tests/project/test_readme.py checks what they print). Each line's and block's time is
printed. Afterwards ``git status
--porcelain`` must be empty: nothing a line writes may land outside ``out/``
(ignored by git).

Two stated exceptions:

- ``python -m pytest`` of the second set-up command runs as ``python -m pytest
  --collect-only -q`` (the suite is found and imports in the fresh environment):
  ``.ci/run`` runs the whole suite on the same commit just before this test, and
  running it twice would double the CI time. ``LSC_README_FULL_SUITE=1`` runs it
  as written.
- the lines that need the native host ecos skip, with the reason, when the
  system library it needs (``libtbb.so.12``, ``apt-get install libtbb12``) is
  missing; under CI (``CI`` set) they fail instead.

Slow (it installs every extra), so it is marked ``install`` and left out of the
default run; ``.ci/run`` runs it (``python -m pytest -m install -s
tests/project/test_readme_shell.py``).
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

from tests.support import ROOT
SUITE = "python -m pytest"
NATIVE_HOST = re.compile(r"\becos\b|lsc-fmu env")


def bash_blocks(text=None):
    """The README's ```bash blocks, each a list of its non-empty lines."""
    text = (ROOT / "README.md").read_text() if text is None else text
    return [[line for line in block.splitlines() if line.strip() and not line.lstrip().startswith("#")]
            for block in re.findall(r"^```bash\n(.*?)^```", text, re.S | re.M)]


def test_readme_starts_with_the_two_commands():
    assert bash_blocks()[0] == [
        'python -m pip install -e ".[fmu]" && python examples/main_job.py',
        'python -m pip install -e ".[test]" && python -m pytest',
    ]


def test_readme_lines_write_under_out():
    """A file a shell line names as an output is under out/ (the clone test checks what they really write)."""
    for line in [line for block in bash_blocks() for line in block]:
        for path in re.findall(r"(?:-o|--plot|--result|--output)\s+(\S+\.\w+)", line):
            assert path.startswith("out/"), line


def page_lines(text, blocks):
    """Every shell line and python block of the page, in order: [(bash line, note)], python blocks as files in `blocks`."""
    lines = []
    for i, (kind, body) in enumerate(re.findall(r"^```(bash|python)\n(.*?)^```", text, re.S | re.M)):
        if kind == "python":
            (blocks / f"block{i}.py").write_text(body)
            lines.append((f"python {blocks / f'block{i}.py'}", "a python block of the README"))
            continue
        for line in [line for line in body.splitlines() if line.strip() and not line.lstrip().startswith("#")]:
            if line.endswith(f"&& {SUITE}") and not os.environ.get("LSC_README_FULL_SUITE"):
                lines.append((f"{line} --collect-only -q", "suite: collected only (.ci/run runs it)"))
            elif NATIVE_HOST.search(line) and not _libtbb():
                if os.environ.get("CI"):
                    pytest.fail(f"libtbb.so.12 is missing (apt-get install libtbb12): cannot run {line!r}")
                print(f"skipped (libtbb.so.12 missing: apt-get install libtbb12): {line}")
            else:
                lines.append((line, ""))
    return lines


def _libtbb():
    found = subprocess.run(["ldconfig", "-p"], capture_output=True, text=True).stdout if shutil.which("ldconfig") else ""
    return "libtbb.so.12" in found


def _script(lines, times, listing=None):
    """One bash script: every line in order, its start and end time and status appended to `times`.

    With `listing`, every file under out/ (path, modification time, size) is appended to it after each
    line, as ``i path mtime size`` (see `written_twice`).
    """
    parts = []
    for i, line in enumerate(lines):
        parts.append(f'__t0=$(date +%s.%N)\n{line}\n__rc=$?\n'
                     f'echo "{i} $__rc $__t0 $(date +%s.%N)" >> "{times}"\n')
        if listing is not None:
            parts.append(f'(cd "$__root" && find out -type f -printf "{i} %p %T@ %s\\n" 2>/dev/null) >> "{listing}"\n')
        parts.append('[ "$__rc" -eq 0 ] || exit "$__rc"\n')
    return ('__root=$(pwd)\n' if listing is not None else "") + "".join(parts)


def written_twice(listing):
    """{file: [indices of the lines that wrote it]} for the files under out/ that more than one line wrote.

    `listing` holds ``i path mtime size`` rows, all files after line i; a line wrote a file that
    appears after it or changed modification time or size.
    """
    after = {}
    for row in listing.splitlines():
        head, mtime, size = row.rsplit(" ", 2)
        i, path = head.split(" ", 1)
        after.setdefault(int(i), {})[path] = (mtime, size)
    writers, before = {}, {}
    for i in sorted(after):
        for path, stamp in after[i].items():
            if before.get(path) != stamp:
                writers.setdefault(path, []).append(i)
        before = after[i]
    return {path: lines for path, lines in writers.items() if len(lines) > 1}


def test_written_twice_names_the_lines():
    listing = "\n".join(["0 out/a.fmu 1.0 10", "1 out/a.fmu 1.0 10", "1 out/b.csv 2.0 5", "2 out/a.fmu 3.0 10",
                          "2 out/b.csv 2.0 5", "2 out/my file.csv 4.0 1"])
    assert written_twice(listing) == {"out/a.fmu": [0, 2]}
    assert written_twice("0 out/a 1.0 1\n1 out/a 1.0 1") == {}


@pytest.mark.install
def test_every_readme_shell_line_on_a_fresh_clone(tmp_path):
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    clone = tmp_path / "lsc"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True, timeout=300)
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    bindir = env_dir / "bin"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "LD_PRELOAD")}
    env.update(VIRTUAL_ENV=str(env_dir), PATH=os.pathsep.join([str(bindir), env.get("PATH", "")]), MPLBACKEND="Agg",
               PIP_DISABLE_PIP_VERSION_CHECK="1")

    blocks = tmp_path / "blocks"  # a folder of its own: the script's folder is first on sys.path
    blocks.mkdir()
    lines, notes = zip(*page_lines((clone / "README.md").read_text(), blocks))

    times = tmp_path / "times.txt"
    listing = tmp_path / "listing.txt"
    (tmp_path / "readme.sh").write_text(_script(lines, times, listing))
    t0 = time.perf_counter()
    with open(tmp_path / "stdout.txt", "w") as out, open(tmp_path / "stderr.txt", "w") as err:
        proc = subprocess.run(["bash", str(tmp_path / "readme.sh")], cwd=clone, env=env, stdout=out, stderr=err,
                              timeout=3600)
    total = time.perf_counter() - t0
    records = [r.split() for r in times.read_text().splitlines()] if times.exists() else []
    print(f"\nREADME shell lines on a fresh clone ({len(records)} of {len(lines)} ran):")
    for i, rc, start, end in records:
        i = int(i)
        print(f"{float(end) - float(start):7.1f} s  rc={rc}  {lines[i]}" + (f"   [{notes[i]}]" if notes[i] else ""))
    print(f"{total:7.1f} s  in all")
    stdout, stderr = (tmp_path / "stdout.txt").read_text(), (tmp_path / "stderr.txt").read_text()
    failed = lines[len(records) - 1] if records else lines[0]  # a failing line is recorded, then the script stops
    assert proc.returncode == 0 and len(records) == len(lines), (failed, stdout[-3000:], stderr[-3000:])

    # no line overwrites what another wrote (a native build replaced the main job's pythonfmu FMU, so the
    # ecos recipe after it never ran on a pythonfmu FMU)
    twice = written_twice(listing.read_text())
    assert not twice, {path: [lines[i] for i in which] for path, which in twice.items()}

    status = subprocess.run(["git", "status", "--porcelain"], cwd=clone, capture_output=True, text=True, check=True)
    assert status.stdout == "", f"the README's lines changed the checkout:\n{status.stdout}"
    # what the lines promise, under out/
    assert "validate_fmu: no problems" in stdout
    assert (clone / "out" / "main_job.png").stat().st_size > 10_000
    for name in ("run.csv", "run.png", "path_control.ssp", "cosim.csv", "study.csv", "study.png"):
        assert (clone / "out" / name).stat().st_size > 0, name
    if _libtbb():
        assert (clone / "out" / "PrescribedPath.csv").stat().st_size > 0
    # the clone's own code ran, not the developer's checkout
    where = subprocess.run([str(bindir / "python"), "-c", "import lsc; print(lsc.__file__)"], env=env, cwd=env_dir,
                           capture_output=True, text=True, check=True).stdout
    assert Path(where.strip()).is_relative_to(clone), where
