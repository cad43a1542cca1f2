"""Helpers shared by the tests and the subprocess runners (plain functions, no fixtures).

The runners (fmu_runner.py, native_runner.py) import this file as scripts run from tests/;
it imports nothing beyond the standard library at module level for that reason.
"""
import contextlib
import os
import signal
import sys
from pathlib import Path

REFERENCE_FMUS_HELP = ("set LSC_REFERENCE_FMUS to a folder of built Modelica Reference FMUs (the layout of their "
                       "release archive: 2.0/Dahlquist.fmu, 3.0/Dahlquist.fmu, ...)")


def reference_fmus(version):
    """The folder of the Modelica Reference FMUs built for FMI `version` ("2.0" or "3.0"), or a skip reason.

    Returns ``(folder, None)`` or ``(None, reason)``. The FMUs are read from ``LSC_REFERENCE_FMUS``, built
    outside this repository (their release archive has this layout); the tests never build third-party code.
    """
    given = os.environ.get("LSC_REFERENCE_FMUS")
    if not given:
        return None, f"Reference FMUs not given: {REFERENCE_FMUS_HELP}"
    folder = Path(given) / version
    if not (folder / "Dahlquist.fmu").is_file():
        return None, f"{folder / 'Dahlquist.fmu'} not found: {REFERENCE_FMUS_HELP}"
    return folder, None


class ImportBlocker:
    """A meta-path finder that makes ``import name`` (and its submodules) fail, as in a host without it."""

    def __init__(self, names):
        self.names = set(names)

    def find_spec(self, name, path=None, target=None):
        if any(name == n or name.startswith(n + ".") for n in self.names):
            raise ImportError(f"import of {name!r} blocked by the test")
        return None


def block_imports(names):
    """Make ``import name`` fail for each of ``names`` in this process (``ImportBlocker``); returns
    ``{name: whether the import is now refused}``, which a runner reports so the test can check the block held."""
    if names:
        sys.meta_path.insert(0, ImportBlocker(names))
    blocked = {}
    for name in names:
        try:
            __import__(name)
            blocked[name] = False
        except ImportError:
            blocked[name] = True
    return blocked


@contextlib.contextmanager
def deadline(seconds, what="still running"):
    """Fail with TimeoutError after `seconds` (a hang guard, not a speed test)."""
    def expired(signum, frame):
        raise TimeoutError(f"{what} after {seconds} s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def lag_spec(**changes):
    """A valid one-state spec, ``tau x' + x = sin t``, with top-level tables replaced by `changes`."""
    spec = {"model": {"name": "Lag"}, "states": {"x": {}}, "parameters": {"tau": {"value": 2.0}},
            "equations": {"A": [["tau"]], "B": [[1]], "f": ["sin(t)"]}}
    spec.update(changes)
    return spec


def spec_problems(spec):
    """The problems `fmu_build.parse_spec` reports for `spec` (it must refuse it)."""
    import pytest

    from fmu_build import SpecError, parse_spec

    with pytest.raises(SpecError) as info:
        parse_spec(spec)
    return info.value.problems
