import os
import re

# One BLAS thread per test process (the pytest workers and every subprocess they start, which inherit the
# environment): the suite runs its processes side by side, and OpenBLAS threads that outnumber the cores
# spin waiting for each other. Set before numpy loads OpenBLAS; a value given in the environment is kept.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from lsc import COMPLETIONS, gallery  # noqa: E402

# (method, lam) pairs that every completion test runs over.
METHOD_LAMS = [("standard", None), ("stabilized", 2.0), ("alternative", 2.0)]


def method_lams():
    assert set(m for m, _ in METHOD_LAMS) == set(COMPLETIONS)
    return METHOD_LAMS


def assert_same_spectrum(found, expected, rtol=1e-8, atol=1e-8):
    """Multisets equal: each expected value matched to its nearest found one."""
    found = list(np.asarray(found, dtype=complex))
    expected = np.asarray(expected, dtype=complex)
    assert len(found) == len(expected), (found, expected)
    for mu in expected:
        j = int(np.argmin([abs(f - mu) for f in found]))
        assert abs(found[j] - mu) <= atol + rtol * abs(mu), (found, expected)
        found.pop(j)


CONSTANT_PROBLEMS = {
    **{f"chain{i}": (lambda i=i: gallery.nilpotent_chain(i)) for i in range(1, 7)},
    **{f"chain{i}-mixed": (lambda i=i: gallery.nilpotent_chain(i, seed=i)) for i in range(1, 7)},
    "pencil-3-2": lambda: gallery.random_pencil(n=12, blocks=(3, 2), seed=1),
    "pencil-4-1-1": lambda: gallery.random_pencil(n=10, blocks=(4, 1, 1), seed=2),
    "mechanical": gallery.mechanical,
    "prescribed_path": gallery.prescribed_path,
}


@pytest.fixture(params=sorted(CONSTANT_PROBLEMS), scope="module")
def problem(request):
    return CONSTANT_PROBLEMS[request.param]()


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
