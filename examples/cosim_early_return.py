"""Early return from fmi3DoStep, side by side with the same runs without it.

The system: an FMI 3.0 C source whose output jumps from 0 to 1 at t_e = 0.37 (``plants.build_event_source3``,
returning early at t_e where allowed) feeding an FMI 2.0 C lag ``x' = -(x - y)`` (``plants.build_scalar_plant``,
exact for the input it receives) on [0, 1]. Exact solution: ``x = 0`` before t_e, ``1 - exp(-(t - t_e))`` after.
Each configuration runs with ``early_return=True`` (the step ends at t_e, every FMU rolled back and stepped there)
and ``early_return=False`` (the FMU handles its event inside the step). Columns: rows of the result, macro steps
(rejected ones after a slash: rolled back and repeated, early returns included), FMU calls (``doStep`` summed over
both FMUs, rolled-back attempts included) and the largest error of the lag's ``x`` over the rows.

Writes out/cosim_early_return.md; with --docs, docs/_generated/cosim_early_return.md.
Run: python examples/cosim_early_return.py [--docs]   (gcc)
"""
import contextlib
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parent / "plants"))
from _docs_output import output_path  # noqa: E402

import plants  # noqa: E402
from fmu_build import cosimulate  # noqa: E402

T_EVENT = 0.37


@contextlib.contextmanager
def counted_do_steps():
    """Count every ``fmi2DoStep`` and ``fmi3DoStep`` made through fmpy in this process."""
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    count, originals = [0], {cls: cls.doStep for cls in (FMU2Slave, FMU3Slave)}

    def wrap(original):
        def doStep(self, *args, **kwargs):  # noqa: N802 (fmpy's name)
            count[0] += 1
            return original(self, *args, **kwargs)
        return doStep

    for cls, original in originals.items():
        cls.doStep = wrap(original)
    try:
        yield count
    finally:
        for cls, original in originals.items():
            cls.doStep = original


def exact(t):
    return np.where(t < T_EVENT, 0.0, 1.0 - np.exp(-(t - T_EVENT)))


def main():
    configurations = [
        ("fixed H = 0.1, jacobi, p = 0", dict(step_size=0.1, algorithm="jacobi")),
        ("fixed H = 0.1, gauss-seidel, p = 0", dict(step_size=0.1)),
        ("fixed H = 0.1, jacobi, p = 1", dict(step_size=0.1, algorithm="jacobi", extrapolation=1)),
        ("fixed H = 0.01, jacobi, p = 1", dict(step_size=0.01, algorithm="jacobi", extrapolation=1)),
        ("step control rtol 1e-4, p = 1", dict(step_size=0.1, step_control=True, rtol=1e-4, extrapolation=1)),
        ("step control rtol 1e-6, p = 1", dict(step_size=0.1, step_control=True, rtol=1e-6, extrapolation=1)),
    ]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        system = {"components": {"src": str(plants.build_event_source3(tmp, "src", T_EVENT)),
                                 "lag": str(plants.build_scalar_plant(tmp, "lag", a=-1.0, b=1.0))},
                  "connections": [("src.y", "lag.u")]}
        for label, kwargs in configurations:
            cells = []
            for early in (True, False):
                with counted_do_steps() as calls:
                    r = cosimulate(system, 1.0, output=["lag.y"], early_return=early, progress=False, **kwargs)
                if not r.success:
                    raise RuntimeError(f"{label}, early_return={early}: {r.message}")
                error = float(np.max(np.abs(r["lag.y"] - exact(r["time"]))))
                cells.append(f"{len(r)} | {r.steps}/{r.rejected} | {calls[0]} | {error:.1e}")
                print(f"{label:<36} early_return={early!s:<5} rows {len(r):>5} steps {r.steps:>5}/{r.rejected:<3} "
                      f"calls {calls[0]:>6} error {error:.1e}")
            rows.append(f"| {label} | " + " | ".join(cells) + " |")
    path = output_path("cosim_early_return.md")
    lines = [f"`python examples/cosim_early_return.py`, run {time.strftime('%Y-%m-%d')} (Python "
             f"{platform.python_version()}): source jumping at t = {T_EVENT} -> lag, [0, 1]; each cell: with early "
             "return | without.", "",
             "| configuration | rows | steps/rejected | FMU calls | error | rows | steps/rejected | FMU calls | error |",
             "|---|---|---|---|---|---|---|---|---|", *rows, ""]
    path.write_text("\n".join(lines))
    print(path)


if __name__ == "__main__":
    main()
