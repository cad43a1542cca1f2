"""A host's implicit integrator taking the FMU's exact Jacobian: CVODE (BDF) on a native Model Exchange FMU.

An FMI host that integrates a Model Exchange FMU with an implicit method needs the Jacobian ``d der(x)/dx``
of the FMU's right-hand side. fmpy's own CVode (``fmpy.sundials.CVodeSolver``) never asks the FMU for it:
it attaches a dense linear solver without a Jacobian function, so CVODE builds one by difference quotients,
one right-hand-side evaluation per state. A native lsc FMU of constant coefficients gives the exact one,
``G``, through ``fmi2GetDirectionalDerivative``.

This script is a small ME host of its own (fmpy's ``FMU2Model`` low-level calls: set time and states, get
derivatives) around scikit-sundae's CVODE (BDF, dense), run twice side by side on the same FMU: once with a
Jacobian callback assembled column by column from ``fmi2GetDirectionalDerivative``, once with CVODE's
difference quotients. The FMU is the prescribed-path problem (`lsc.gallery.prescribed_path`, index 3), the
alternative completion at ``lambda = 1e4``: every eigenvalue of ``G`` is ``-lambda``, a stiff ODE. Reported per
run: right-hand-side evaluations (counted in the callback, those of the difference quotients included),
CVODE's Jacobian evaluations, FMU calls, wall time (best of the repeats) and the largest error against the
exact solution; and how far the callback's Jacobian is from lsc's own ``G``.

Writes out/host_jacobian.md (with --docs, docs/_generated/host_jacobian.md); --json prints one JSON line.
Run: python examples/host_jacobian.py [--docs] [--json] [--stop T] [--lam L] [--repeats R]
"""
import argparse
import json
import sys
import tempfile
import time
import tomllib
from ctypes import c_double
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _docs_output import FLAG, HELP, printed_to_docs  # noqa: E402

import lsc  # noqa: E402
from lsc import gallery  # noqa: E402

SPEC = Path(__file__).parent / "specs" / "prescribed_path.toml"
RTOL, ATOL = 1e-8, 1e-10


def build(folder, lam):
    """The native FMI 2.0 FMU (Model Exchange and Co-Simulation) of the prescribed-path spec at ``lam``."""
    from fmu_build import build_fmu

    spec = tomllib.loads(SPEC.read_text())
    spec["completion"]["lam"] = float(lam)
    spec["model"]["name"] = "PrescribedPathStiff"
    return build_fmu(spec, folder, target="native", fix_parameters=True)


class Host:
    """One Model Exchange instance in continuous-time mode, with counted FMU calls.

    ``rhs(t, y, yp)``: ``fmi2SetTime``, ``fmi2SetContinuousStates``, ``fmi2GetDerivatives``.
    ``jac(t, y, yp, JJ)``: time and states set, then ``fmi2GetDirectionalDerivative`` of every derivative
    with respect to one state per call (a unit seed): the columns of ``d der(x)/dx``.
    """

    def __init__(self, fmu, lam):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Model

        md = read_model_description(str(fmu))
        self.unzipped = extract(str(fmu))
        self.model = FMU2Model(guid=md.guid, unzipDirectory=self.unzipped,
                               modelIdentifier=md.modelExchange.modelIdentifier, instanceName="host")
        self.ders = [d.variable.valueReference for d in md.derivatives]
        self.states = [d.variable.derivative.valueReference for d in md.derivatives]
        self.names = [d.variable.derivative.name for d in md.derivatives]
        self.n = len(self.states)
        lam_ref = next(v.valueReference for v in md.modelVariables if v.name == "lambda")
        m = self.model
        m.instantiate()
        m.setupExperiment(startTime=0.0)
        m.setReal([lam_ref], [float(lam)])
        m.enterInitializationMode()
        m.exitInitializationMode()
        while True:  # event iteration at the start (none expected: FMI asks for it)
            if not m.newDiscreteStates()[0]:
                break
        m.enterContinuousTimeMode()
        self._x, self._dx = (c_double * self.n)(), (c_double * self.n)()
        m.getContinuousStates(self._x, self.n)
        self.x0 = np.array(self._x[:])
        self.rhs_calls = self.jac_calls = self.fmu_calls = 0
        self.jacobians = []  # every Jacobian the callback returned

    def _set(self, t, y):
        self.model.setTime(float(t))
        self._x[:] = [float(v) for v in y]
        self.model.setContinuousStates(self._x, self.n)
        self.fmu_calls += 2

    def rhs(self, t, y, yp):
        self._set(t, y)
        self.model.getDerivatives(self._dx, self.n)
        self.fmu_calls += 1
        self.rhs_calls += 1
        yp[:] = self._dx[:]

    def jac(self, t, y, yp, JJ):
        self._set(t, y)
        for j, state in enumerate(self.states):
            JJ[:, j] = self.model.getDirectionalDerivative(self.ders, [state], [1.0])
            self.fmu_calls += 1
        self.jac_calls += 1
        self.jacobians.append(np.array(JJ, dtype=float))

    def free(self):
        self.model.terminate()
        self.model.freeInstance()


def integrate(fmu, lam, t_eval, with_jacobian):
    """One CVODE (BDF) run on a fresh instance; returns its counts, wall time, states and Jacobians."""
    from sksundae.cvode import CVODE

    host = Host(fmu, lam)
    try:
        solver = CVODE(host.rhs, method="BDF", rtol=RTOL, atol=ATOL, max_num_steps=100000,
                       jacfn=host.jac if with_jacobian else None)
        start = time.perf_counter()
        result = solver.solve(t_eval, host.x0)
        wall = time.perf_counter() - start
    finally:
        host.free()
    return {"success": bool(result.success), "message": str(result.message), "t": np.asarray(result.t),
            "y": np.asarray(result.y), "rhs": host.rhs_calls, "nfev": int(result.nfev), "njev": int(result.njev),
            "jac_callbacks": host.jac_calls, "fmu_calls": host.fmu_calls, "wall": wall, "jacobians": host.jacobians,
            "names": host.names}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--stop", type=float, default=10.0, help="end time (default 10)")
    parser.add_argument("--lam", type=float, default=1e4, help="the completion's rate lambda (default 1e4)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each variant; the best wall time counts")
    parser.add_argument("--json", action="store_true", help="print one JSON line with the numbers")
    parser.add_argument(FLAG, action="store_true", help=HELP)
    args = parser.parse_args(argv)

    problem = gallery.prescribed_path()
    G = lsc.complete(problem.dae, "alternative", lam=args.lam).maps().G[0]
    t_eval = np.linspace(0.0, args.stop, 201)
    exact = np.array([problem.exact(t) for t in t_eval])
    with tempfile.TemporaryDirectory() as tmp:
        fmu = build(tmp, args.lam)
        runs = {}
        for _ in range(max(1, args.repeats)):  # the variants alternate: both see the same machine load
            for name, with_jacobian in (("exact Jacobian", True), ("difference quotients", False)):
                r = integrate(fmu, args.lam, t_eval, with_jacobian)
                if name not in runs or r["wall"] < runs[name]["wall"]:
                    runs[name] = r
    rows = {}
    for name, r in runs.items():
        if r["success"] and r["y"].shape == exact.shape:
            err = float(np.max(np.abs(r["y"] - exact)) / np.max(np.abs(exact)))
        else:
            err = float("nan")
        J = r["jacobians"]
        jac_vs_G = max((float(np.max(np.abs(j - G)) / np.max(np.abs(G))) for j in J), default=None)
        rows[name] = {k: r[k] for k in ("success", "message", "rhs", "nfev", "njev", "jac_callbacks", "fmu_calls",
                                        "wall")}
        rows[name].update(error=err, jacobian_vs_G=jac_vs_G)
    if args.json:
        print(json.dumps({"lam": args.lam, "stop": args.stop, "rtol": RTOL, "atol": ATOL, "runs": rows,
                          "states": runs["exact Jacobian"]["names"]}))
        return rows
    title = "A host's implicit integrator taking the FMU's Jacobian"
    with printed_to_docs("host_jacobian", title):
        print(f"CVODE (BDF, dense, scikit-sundae) on the native Model Exchange FMU of prescribed_path (index 3), "
              f"alternative completion, lambda = {args.lam:g} (every eigenvalue of G is -lambda); rtol = {RTOL:g}, "
              f"atol = {ATOL:g}, t in [0, {args.stop:g}], 201 output points; best wall time of {args.repeats}.")
        print("rhs: right-hand-side evaluations by the host's count (difference quotients included); "
              "Jacobians: CVODE's; FMU calls: fmi2SetTime, fmi2SetContinuousStates, fmi2GetDerivatives and "
              "fmi2GetDirectionalDerivative; error: largest |x - x*| / max |x*| against the exact solution.")
        print()
        print(f"{'Jacobian':<22} {'rhs':>7} {'Jacobians':>10} {'FMU calls':>10} {'wall [ms]':>10} {'error':>9}  "
              "callback J vs lsc's G")
        for name, r in rows.items():
            versus = f"{r['jacobian_vs_G']:.1e}" if r["jacobian_vs_G"] is not None else "-"
            print(f"{name:<22} {r['rhs']:>7} {r['njev']:>10} {r['fmu_calls']:>10} {1e3 * r['wall']:>10.2f} "
                  f"{r['error']:>9.1e}  {versus}" + ("" if r["success"] else f"  FAILED: {r['message']}"))
        a, b = rows["exact Jacobian"], rows["difference quotients"]
        print()
        print(f"difference quotients / exact Jacobian: rhs {b['rhs'] / a['rhs']:.2f}, FMU calls "
              f"{b['fmu_calls'] / a['fmu_calls']:.2f}, wall time {b['wall'] / a['wall']:.2f}")
    return rows


if __name__ == "__main__":
    main()
