"""The two co-simulation scenarios: their FMUs, SSP files and monolithic references.

1. ``path``: the DAE FMU ``PathControl`` (prescribed path, index 3) computes the force
   F = u + Kp (y - ym) + Kd (v - vm) for a C mass-spring-damper plant (``MSD``) whose
   measured position and velocity it receives.
2. ``loop``: a plant ``w' = -w + g x2`` (pythonfmu ``LagPlant``, or the C plant ``Lag`` with
   output derivatives) feeds the index-2 ``Follower`` (x1' + x2 = 0, x1 = w), whose flow x2
   goes back to the plant: a loop through a differentiated input. Exact solution
   w = x1 = exp(-t / (1 + g)), x2 = w / (1 + g).
"""
from pathlib import Path

import numpy as np

import plants

HERE = Path(__file__).parent
SSP_DIR = HERE.parent / "ssp"

# plant of scenario 1 (deliberately not the DAE's model: the feedback has work to do)
MP, CP, KP_PLANT = 1.2, 0.3, 2.5
X0_PLANT = (0.1, 2.5)


def build_path_system(dest, method="standard", lam=10.0, name="path", target="pythonfmu"):
    """``dest/name.ssp`` for scenario 1 (and the FMUs beside it); ``target`` of the DAE FMU."""
    from fmu_build import build_fmu

    dest = Path(dest)
    dae = build_fmu(SSP_DIR / "path_control.toml", dest / "fmus", method=method, lam=lam, target=target,
                    fix_parameters=target == "native")
    plant = plants.build_linear_plant(dest / "fmus", "MSD", [[0.0, 1.0], [-KP_PLANT / MP, -CP / MP]], [0.0, 1.0 / MP],
                                      X0_PLANT, output_names=("x", "v"), input_name="F")
    return plants.write_ssp(dest / f"{name}.ssp", name, {"dae": dae, "plant": plant},
                            [("plant.x", "dae.ym"), ("plant.v", "dae.vm"), ("dae.F", "plant.F")])


def path_reference(t, Kp=20.0, Kd=6.0, m=1.0, c=0.5, k=2.0):
    """Monolithic solution of scenario 1: the DAE and the plant as one index-3 DAE, by lsc (rtol 1e-12).

    States (y, v, u, x, w): y' = v, m v' + c v + k y = u, y = p(t), x' = w,
    MP w' + CP w + KP x = u + Kp (y - x) + Kd (v - w).
    """
    import sympy

    import lsc

    s = sympy.Symbol("t")
    A = np.diag([1.0, m, 0.0, 1.0, MP])
    B = np.array([[0, -1, 0, 0, 0], [k, c, -1, 0, 0], [1, 0, 0, 0, 0], [0, 0, 0, 0, -1],
                  [-Kp, -Kd, -1, KP_PLANT + Kp, CP + Kd]], dtype=float)
    f = sympy.Matrix([0, 0, sympy.sin(s) + sympy.sin(3 * s) / 2, 0, 0])
    dae = lsc.LinearDAE(A, B, f)
    x0 = [0.0, 2.5, 1.25, *X0_PLANT]
    t = np.asarray(t, dtype=float)
    sol = lsc.solve_dae(dae, (t[0], t[-1]), x0, completion="alternative", lam=1.0, method="DOP853", t_eval=t,
                        rtol=1e-13, atol=1e-13)
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.x


def build_loop_system(dest, g=0.2, plant="pythonfmu", method="alternative", lam=10.0, name=None, dae="lsc"):
    """``dest/name.ssp`` for scenario 2 with the pythonfmu lag or the C lag (output derivatives).

    ``dae="lsc"``: our pythonfmu DAE FMU (values only); ``dae="native"``: our native C DAE FMU
    (``build_fmu(..., target="native")``: receives input derivatives, canInterpolateInputs);
    ``dae="exact"``: a hand-written C follower x1 = w, x2 = -w' (exact, for comparison).
    """
    from fmu_build import build_fmu

    dest = Path(dest)
    if dae in ("lsc", "native"):
        dae = build_fmu(SSP_DIR / "follower.toml", dest / "fmus", method=method, lam=lam,
                        target="native" if dae == "native" else "pythonfmu")
    else:
        dae = plants.build_linear_plant(dest / "fmus", "ExactFollower", [[0.0, 0.0], [0.0, 0.0]], [0.0, 0.0],
                                        (1.0, 1.0 / (1.0 + g)), output_names=("x1", "x2"), input_name="w",
                                        follower=True)
    if plant == "pythonfmu":
        # a model name per g: pythonfmu runs one model module per name in a process (the master refuses a second)
        lag = plants.build_lag_plant(dest / "fmus", name="LagPlant_g" + f"{g:g}".replace(".", "_").replace("-", "m"), g=g)
        w, u = "w", "u"
    else:
        lag = plants.build_linear_plant(dest / "fmus", "Lag", [[-1.0, 0.0], [0.0, 0.0]], [g, 0.0], (1.0, 0.0),
                                        output_names=("w", "unused"), input_name="u")
        w, u = "w", "u"
    name = name or f"loop_{plant}"
    return plants.write_ssp(dest / f"{name}.ssp", name, {"dae": dae, "plant": lag},
                            [(f"plant.{w}", "dae.w"), ("dae.x2", f"plant.{u}")])


def loop_reference(t, g):
    """Exact solution of scenario 2: (w, x1, x2)."""
    w = np.exp(-np.asarray(t) / (1.0 + g))
    return w, w, w / (1.0 + g)


def build_damper_loop(dest, plant_x0=(1.0, 0.0), name="damper_loop", method="alternative", lam=10.0,
                      target="pythonfmu"):
    """A second loop through a differentiated input: a C mass-spring-damper whose position x
    feeds the Follower (x1 = x, x2 = -x'); the flow x2 goes back as the force: m x'' + c x' + k x = x2.
    Here x' does not depend on the force directly (x has relative degree 2), unlike scenario 2."""
    from fmu_build import build_fmu

    dest = Path(dest)
    dae = build_fmu(SSP_DIR / "follower.toml", dest / "fmus", method=method, lam=lam, target=target)
    plant = plants.build_linear_plant(dest / "fmus", "MSD", [[0.0, 1.0], [-KP_PLANT / MP, -CP / MP]], [0.0, 1.0 / MP],
                                      plant_x0, output_names=("x", "v"), input_name="F")
    return plants.write_ssp(dest / f"{name}.ssp", name, {"dae": dae, "plant": plant},
                            [("plant.x", "dae.w"), ("dae.x2", "plant.F")])


def damper_loop_reference(t, x0=(1.0, 0.0)):
    """Exact (x, v) of MP x'' + (CP + 1) x' + KP x = 0."""
    from scipy.linalg import expm

    A = np.array([[0.0, 1.0], [-KP_PLANT / MP, -(CP + 1.0) / MP]])
    return np.array([expm(A * s) @ np.asarray(x0) for s in np.asarray(t)]).T
