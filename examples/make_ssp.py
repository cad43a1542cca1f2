"""Write a co-simulation system for ``lsc-fmu cosim``: out/path_control.ssp.

The system of examples/ssp/path_control.toml: the DAE FMU ``PathControl``
(a prescribed path, index 3, built from that spec by ``fmu_build.build_fmu``)
computes the force F = u + Kp (y - ym) + Kd (v - vm) for a C mass-spring-damper
plant ``MSD`` (compiled with gcc from examples/plants/linear_plant.c), whose
measured position and velocity it receives. The two FMUs go to out/fmus/, the
SSP archive (SystemStructure.ssd and both FMUs) to out/path_control.ssp.

Run:  python examples/make_ssp.py [DEST]   (DEST: folder of the .ssp, default out)
"""
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "plants"))
import scenarios  # noqa: E402  (examples/plants: the scenarios the co-simulation examples and tests share)


def main(dest=HERE.parent / "out"):
    ssp = scenarios.build_path_system(Path(dest), name="path_control")
    print(f"wrote {os.path.relpath(ssp)}")


if __name__ == "__main__":
    main(*sys.argv[1:2])
