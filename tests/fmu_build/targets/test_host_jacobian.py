"""examples/host_jacobian.py: CVODE (BDF) on a native Model Exchange FMU, with the Jacobian from
fmi2GetDirectionalDerivative and with CVODE's difference quotients, in a subprocess (the FMU runs there).

Both runs must reach the exact solution of the prescribed-path problem within their tolerance, and every
Jacobian the host's callback assembled from the FMU must equal lsc's own ``G`` to 1e-12 (relative).
"""
import json
import shutil
import subprocess
import sys

import pytest

from tests.support import ROOT

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the native FMU is compiled with gcc")


def test_host_jacobian_example_reaches_the_exact_solution_and_takes_G():
    pytest.importorskip("sksundae", reason="scikit-sundae (CVODE) is not installed")
    proc = subprocess.run([sys.executable, str(ROOT / "examples" / "host_jacobian.py"), "--json", "--stop", "2",
                           "--repeats", "1"], capture_output=True, text=True, timeout=600, cwd=str(ROOT))
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    assert proc.returncode == 0 and lines, proc.stdout[-2000:] + proc.stderr[-2000:]
    out = json.loads(lines[-1])
    assert out["states"] == ["y", "v", "u"]
    exact, quotients = out["runs"]["exact Jacobian"], out["runs"]["difference quotients"]
    for name, r in out["runs"].items():
        assert r["success"], (name, r["message"])
        # rtol 1e-8 per step: the global error stays within 100 rtol of the largest state
        assert r["error"] <= 100 * out["rtol"], (name, r["error"])
        assert r["njev"] >= 1, (name, r)
    # CVODE took every Jacobian from the callback, and each equals G; without it none was asked for
    assert exact["jac_callbacks"] == exact["njev"], exact
    assert exact["jacobian_vs_G"] is not None and exact["jacobian_vs_G"] <= 1e-12, exact
    assert quotients["jac_callbacks"] == 0 and quotients["jacobian_vs_G"] is None, quotients
    # the difference quotients cost one right-hand side per state and Jacobian on top of CVODE's own count
    assert quotients["rhs"] == quotients["nfev"] + 3 * quotients["njev"], quotients
    assert exact["rhs"] == exact["nfev"], exact
