import os
import re

# One BLAS thread per test process (the pytest workers and every subprocess they start, which inherit the
# environment): the suite runs its processes side by side, and OpenBLAS threads that outnumber the cores
# spin waiting for each other. Set before numpy loads OpenBLAS; a value given in the environment is kept.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402

# The runners are scripts, each run in a process of its own (they block imports and import their neighbour
# helpers.py as a script does), never modules for --doctest-modules to import.
collect_ignore_glob = ["support/*_runner.py"]


# -- In CI a missing FMU host or external tool is a failure, not a skip ----------
# The FMU tests skip when a host (fmpy, pythonfmu, libcosimpy, ecos) is not
# installed, and the tests against tools nobody here wrote skip when the
# variable naming them is not set, so the test command works on a bare
# machine. CI installs every host and sets every tool's variable (.ci/run),
# and there such a skip would hide a host that no longer installs or loads, or
# a tool that is no longer found: with CI=true it fails instead.
FMU_HOSTS = ("fmpy", "pythonfmu", "libcosimpy", "ecospy", "ecos")
EXTERNAL_TOOLS = ("LSC_REFERENCE_FMUS", "LSC_FMUCHECK", "LSC_FMUSIM")  # the variables their skip reasons name


def _in_ci():
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


def _host_skip_reason(report):
    """The skip reason if `report` is a skip that names an FMU host or an external tool's variable, else None."""
    if not report.skipped or hasattr(report, "wasxfail"):
        return None
    longrepr = report.longrepr
    reason = longrepr[2] if isinstance(longrepr, tuple) and len(longrepr) == 3 else str(longrepr)
    return reason if re.search(r"\b(%s)\b" % "|".join(FMU_HOSTS + EXTERNAL_TOOLS), reason) else None


def _fail_host_skip(report):
    reason = _host_skip_reason(report)
    if reason is not None and _in_ci():
        report.outcome = "failed"
        report.longrepr = f"CI=true: an FMU-host or external-tool test must run, but it skipped: {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    _fail_host_skip(outcome.get_result())


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    _fail_host_skip(outcome.get_result())
