"""fmu_build.cosim: algebraic loops solved by Newton's method with the FMUs' directional derivatives.

The loop of test_cosim_truth: ``z1 = 1 + u1`` (or ``x + u1`` with ``x = e^t``), ``z2 = g u2``, both direct
feedthrough, ``z1 -> u2``, ``z2 -> u1``: exact ``z1 = 1 / (1 - g)`` (``e^t / (1 - g)``). The scalar C plants
(examples/plants/scalar.c) declare and implement ``fmi2GetDirectionalDerivative`` when built with
``directional=factor``: exact for factor 1, a lying FMU for another factor.
"""
import shutil
import sys

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import PLANTS, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the test FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))

GAINS = (-1.0, -0.999, 0.999, 1.001)
NATIVE_GAIN = -1.998  # half of it through the native FMU's w = x + 0.5 p


def _tag(g):
    return f"{g:+.3f}".replace("-", "m").replace("+", "p").replace(".", "_")


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    import plants

    d = tmp_path_factory.mktemp("newton_fmus")
    out = {"one": plants.build_scalar_plant(d, "OneD", 0.0, 0.0, 0.0, 1.0, 1.0, directional=1.0),
           "exp": plants.build_scalar_plant(d, "ExpD", 1.0, 0.0, 1.0, 1.0, 0.0, x0=1.0, directional=1.0),
           "exp_plain": plants.build_scalar_plant(d, "ExpPlain", 1.0, 0.0, 1.0, 1.0, 0.0, x0=1.0)}
    for g in GAINS + (NATIVE_GAIN,):
        out[g] = plants.build_scalar_plant(d, "GD" + _tag(g), 0.0, 0.0, 0.0, g, 0.0, directional=1.0)
        out[("plain", g)] = plants.build_scalar_plant(d, "GP" + _tag(g), 0.0, 0.0, 0.0, g, 0.0)
    for g, factor in ((0.999, 2.0), (0.999, 1.5), (1.001, 0.5), (0.2, 3.0)):
        out[("lying", g, factor)] = plants.build_scalar_plant(d, f"GL{_tag(g)}x{int(10 * factor)}", 0.0, 0.0, 0.0, g,
                                                              0.0, directional=factor)
    # the loop through a unit conversion: one.z in m feeds g.u in cm (x 100); g.z in m feeds one.u in m
    defs = {"m": {"m": 1}, "cm": {"m": 1, "factor": 0.01}}
    out["one_m"] = plants.build_scalar_plant(d, "OneM", 0.0, 0.0, 0.0, 1.0, 1.0, directional=1.0,
                                             units={"u": "m", "z": "m"}, unit_definitions=defs)
    out["g_cm"] = plants.build_scalar_plant(d, "GCm", 0.0, 0.0, 0.0, 0.00999, 0.0, directional=1.0,
                                            units={"u": "cm", "z": "m"}, unit_definitions=defs)
    return {k: str(v) for k, v in out.items()}


def loop(one, g):
    return {"components": {"one": one, "g": g}, "connections": [("one.z", "g.u"), ("g.z", "one.u")]}


PACK = """
def pack(r):
    return {"t": r["time"].tolist(), "z": r["one.z"].tolist(), "success": bool(r.success), "message": r.message,
            "gains": list(r.loop_gains), "stats": dict(getattr(r, "loop_stats", {}) or {}),
            "warned": [str(w.message) for w in caught if "Newton" in str(w.message)]}
"""


def cosim(system, iterations, stop=1.0, H=0.1):
    out, _ = run(PACK + f"""
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    r = cosimulate({system!r}, {stop!r}, {H!r}, iterations={iterations}, output=["one.z"])
print(json.dumps(pack(r)))
""")
    return out


@pytest.mark.parametrize("iterations", [0, 50])
@pytest.mark.parametrize("g", GAINS)
def test_a_loop_with_directional_derivatives_is_solved_by_newton_or_refused(fmus, g, iterations):
    """With every FMU on the loop declaring directional derivatives the loop is solved by Newton's method
    (exact: one step for a linear loop) to 1e-8 of 1 / (1 - g), or a cut loop of |g| >= 1 is refused."""
    out = cosim(loop(fmus["one"], fmus[g]), iterations)
    exact = 1.0 / (1.0 - g)
    if out["success"]:
        assert np.abs(np.array(out["z"]) - exact).max() <= 1e-8 * abs(exact), (out["z"][-3:], exact)
    else:
        assert "algebraic loop" in out["message"] and "gain" in out["message"], out["message"]
        assert abs(g) >= 1 and iterations == 0, out["message"]
    assert out["stats"]["method"] == "newton", out["stats"]
    assert out["stats"]["fallbacks"] == 0 and not out["warned"], (out["stats"], out["warned"])
    assert abs(out["gains"][0] - g) <= 1e-12, out["gains"]  # the gain from the exact Jacobian
    if iterations:
        # the solve at the start from 0: one Newton step and the pass that confirms it
        assert out["stats"]["passes"] <= out["stats"]["solves"] + 1, out["stats"]


def test_the_loop_jacobian_carries_the_connections_unit_factors(fmus):
    """one.z (m) -> g.u (cm): the value arrives multiplied by 100, so the loop gain is 100 * 0.00999 = 0.999 and
    z1 = 1 / (1 - 0.999) = 1000. A Jacobian without the factor (gain 0.00999) would not reduce the residual and
    Newton's method would be given up; with it, one step solves the loop."""
    out = cosim(loop(fmus["one_m"], fmus["g_cm"]), 50)
    assert out["success"], out["message"]
    assert np.abs(np.array(out["z"]) - 1000.0).max() <= 1e-8 * 1000.0, out["z"][-3:]
    assert out["stats"]["method"] == "newton" and out["stats"]["fallbacks"] == 0, (out["stats"], out["warned"])
    assert abs(out["gains"][0] - 0.999) <= 1e-12, out["gains"]


def test_newton_takes_fewer_passes_than_anderson_side_by_side(fmus):
    """z1 = e^t + u1, z2 = 0.999 u2: the fixed point moves with t, each exchange solves it again from the last
    one (and once more, unmoved, in the step iteration). From a moved point Anderson needs three passes of the
    exchange plan, Newton two and one directional derivative per FMU on the loop; both reach e^t / (1 - g) to
    1e-8. Measured: 33 passes + 24 derivative calls against 54 passes; FMU calls (a pass: two gets, two sets)
    156 against 216."""
    g = 0.999
    runs = {"newton": cosim(loop(fmus["exp"], fmus[g]), 50), "anderson": cosim(loop(fmus["exp_plain"],
                                                                                     fmus[("plain", g)]), 50)}
    calls = {}
    for method, out in runs.items():
        assert out["success"], out["message"]
        t = np.array(out["t"])
        exact = np.exp(t) / (1.0 - g)
        err = np.abs(np.array(out["z"]) - exact).max() / np.abs(exact).max()
        assert err <= 1e-8, (method, err)
        stats = out["stats"]
        assert stats["method"] == method and stats["fallbacks"] == 0, stats
        calls[method] = (stats["passes"], 4 * stats["passes"] + stats["derivative_calls"])
    assert runs["newton"]["stats"]["solves"] == runs["anderson"]["stats"]["solves"]
    assert calls["newton"][0] <= 0.7 * calls["anderson"][0], calls
    assert calls["newton"][1] <= 0.8 * calls["anderson"][1], calls


@pytest.mark.parametrize("factor", [2.0, 1.5])
def test_a_lying_fmu_in_an_iterated_loop_falls_back_to_anderson_with_the_reason(fmus, factor):
    """g = 0.999 declaring dz/du = factor * 0.999: the Newton step does not reduce the fixed-point residual;
    the master says so and solves the loop by Anderson acceleration: the right answer, not a wrong one."""
    out = cosim(loop(fmus["one"], fmus[("lying", 0.999, factor)]), 50)
    assert out["success"], out["message"]
    assert np.abs(np.array(out["z"]) - 1000.0).max() <= 1e-8 * 1000.0, out["z"][-3:]
    assert out["stats"]["method"] == "anderson" and out["stats"]["fallbacks"] >= 1, out["stats"]
    assert out["warned"] and "directional derivatives" in out["warned"][0] and "g" in out["warned"][0], out["warned"]
    assert abs(out["gains"][0] - 0.999) <= 1e-6, out["gains"]  # measured, not the declared 1.998


def test_a_lying_fmu_cannot_hide_a_cut_loop_beyond_unit_gain(fmus):
    """g = 1.001 declaring half of it: its Jacobian would pass the gain check (0.5005); checked by one pass
    against the map itself, the gain is measured and the cut loop refused as without derivatives."""
    out = cosim(loop(fmus["one"], fmus[("lying", 1.001, 0.5)]), 0)
    assert not out["success"] and "gain 1.001" in out["message"], out["message"]
    assert out["warned"], out


def test_a_lying_fmu_whose_newton_iteration_still_contracts_converges_to_the_fixed_point(fmus):
    """g = 0.2 declaring 0.6: Newton with the wrong slope still contracts (rate 1/3); every result is checked
    by the fixed-point residual, so it ends at 1 / (1 - 0.2) to 1e-8 (or falls back), never elsewhere."""
    out = cosim(loop(fmus["one"], fmus[("lying", 0.2, 3.0)]), 50)
    assert out["success"], out["message"]
    assert np.abs(np.array(out["z"]) - 1.25).max() <= 1e-8 * 1.25, out["z"][-3:]
    assert abs(out["gains"][0] - 0.2) <= 1e-6, out["gains"]


# a native lsc DAE FMU on the loop (FMI 2.0 and 3.0): x' = -x + p, output w = x + 0.5 p (direct feedthrough)
NATIVE = {"model": {"name": "LagOut"}, "states": {"x": {"start": 1.0}}, "inputs": {"p": {"start": 0.0}},
          "outputs": {"w": {"expr": "x + 0.5*p"}}, "equations": {"A": [[1]], "B": [[1]], "f": ["p"]},
          "completion": {"method": "alternative", "lam": 5.0}}


@pytest.mark.parametrize("version", [2, 3])
def test_a_native_fmu_on_the_loop_gives_newton_its_derivatives(fmus, tmp_path, version):
    """dae.w -> g.u, g.z = -1.998 u -> dae.p: the loop gain is 0.5 * -1.998 = -0.999, read from the native
    FMU's fmi2/fmi3GetDirectionalDerivative (FMI 3.0: providesDirectionalDerivatives, which fmpy does not read).
    The run with Newton's method gives the Anderson run's numbers (loops solved to the same tolerance) with
    two passes per moved solve instead of three."""
    from fmu_build import build_fmu

    dae = build_fmu(NATIVE, tmp_path, target="native", fmi_version=version)
    runs = {}
    for method, g in (("newton", fmus[-1.998]), ("anderson", fmus[("plain", -1.998)])):
        system = {"components": {"dae": str(dae), "g": g}, "connections": [("dae.w", "g.u"), ("g.z", "dae.p")]}
        out, _ = run(PACK.replace('r["one.z"]', 'r["dae.x"]') + f"""
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    r = cosimulate({system!r}, 1.0, 0.05, iterations=20, output=["dae.x"])
print(json.dumps(pack(r)))
""")
        assert out["success"], out["message"]
        assert out["stats"]["method"] == method and out["stats"]["fallbacks"] == 0, out["stats"]
        runs[method] = out
    assert abs(runs["newton"]["gains"][0] + 0.999) <= 1e-12, runs["newton"]["gains"]
    x_newton, x_anderson = np.array(runs["newton"]["z"]), np.array(runs["anderson"]["z"])
    assert np.abs(x_newton - x_anderson).max() <= 1e-9, np.abs(x_newton - x_anderson).max()
    assert runs["newton"]["stats"]["passes"] * 3 <= runs["anderson"]["stats"]["passes"] * 2 + 3, \
        (runs["newton"]["stats"], runs["anderson"]["stats"])


# -- the iteration itself (no FMU) ----------------------------------------------------------------------------

def _tol(x):
    return 1e-12 * (1.0 + np.abs(x))


@pytest.mark.parametrize("a", [0.9, 0.99])
def test_newton_solves_a_nonlinear_loop_in_fewer_passes_than_anderson(a):
    """G(x) = M a tanh(x) + 0.5 (two coupled values): the gain a M sech^2(x) is no constant; from 0 the full
    Newton step overshoots and is shortened, then the iteration converges quadratically."""
    from fmu_build.cosim._loops import anderson, newton

    M = np.array([[0.6, 0.3], [0.2, 0.7]])

    def G(x):
        return M @ (a * np.tanh(x)) + 0.5

    def jac(x):
        return M * (a / np.cosh(x) ** 2)

    fn = newton(G, jac, np.zeros(2), _tol, 50)
    fa = anderson(G, np.zeros(2), _tol, 50)
    assert fn.converged and fa.converged, (fn.reason, fn.evaluations, fa.evaluations)
    assert np.abs(G(fn.x) - fn.x).max() <= 1e-11 and np.abs(fn.x - fa.x).max() <= 1e-10
    assert fn.evaluations <= 8 and fn.evaluations < fa.evaluations, (fn.evaluations, fa.evaluations)


def test_newton_gives_up_with_the_reason_where_no_step_reduces_the_residual():
    """A wrong slope (1.998 for 0.999): every shortened step increases the residual; the tolerance's weights
    (growing with |x|) must not make a step away from the fixed point look like progress."""
    from fmu_build.cosim._loops import newton

    fp = newton(lambda x: 0.999 * x + 1.0, lambda x: np.array([[1.998]]), np.zeros(1), _tol, 50)
    assert not fp.converged and fp.reason.startswith("no Newton step reduced the residual"), fp.reason
    assert fp.evaluations == 5 and fp.x[0] == 0.0  # the step and three shortenings; x left where it was


def test_a_newton_step_at_the_rounding_floor_is_accepted_when_converged():
    """A step that cannot reduce a residual already within the tolerance enough is no failure."""
    from fmu_build.cosim._loops import newton

    noise = iter([1.2, 2.0])  # G(x) - x: 1.2 tolerances at x0 = 2, then 0.8 after the exact step

    def G(x):
        return 0.5 * x + 1.0 + next(noise) * _tol(np.array([2.0]))

    fp = newton(G, lambda x: np.array([[0.5]]), np.array([2.0]), _tol, 10)
    assert fp.converged and not fp.reason and fp.evaluations == 2, (fp.reason, fp.evaluations)
