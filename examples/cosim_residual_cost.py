"""What reading ``constraint_residual`` costs per communication step (scenario 1's DAE FMU).

The master reads only connected and requested variables; this measures what a run that also
asks for the residual pays: ``fmi2GetReal`` of the connected output ``F`` alone and of ``F``
with ``constraint_residual``, after a step, best of 5 repeats of 2,000 reads (one process,
side by side). Writes out/cosim_residual_cost.md (docs/_generated/ with --docs).

Run: PYTHONPATH=. python examples/cosim_residual_cost.py
"""
import sys
import tempfile
import timeit
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "plants"))
import scenarios  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _docs_output import output_folder  # noqa: E402

OUT = output_folder()  # out/; docs/_generated with --docs


def main():
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    tmp = Path(tempfile.mkdtemp(prefix="cosim_cost_"))
    scenarios.build_path_system(tmp)
    path = str(tmp / "fmus" / "PathControl.fmu")
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="dae")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.doStep(0.0, 0.01)
    n = 2000
    only = min(timeit.repeat(lambda: fmu.getReal([vr["F"]]), number=n, repeat=5)) / n
    both = min(timeit.repeat(lambda: fmu.getReal([vr["F"], vr["constraint_residual"]]), number=n, repeat=5)) / n
    clock = [0.01]  # each step starts where the last one ended (the FMU refuses any other communication point)

    def one_step():
        fmu.setReal([vr["ym"]], [0.01])
        fmu.doStep(clock[0], 0.01)
        clock[0] += 0.01

    step = min(timeit.repeat(one_step, number=50, repeat=3)) / 50
    fmu.terminate()
    fmu.freeInstance()
    lines = ["| read per communication step | µs |", "|---|---|",
             f"| F (connected) | {only * 1e6:.1f} |", f"| F and constraint_residual | {both * 1e6:.1f} |",
             f"| for scale: one doStep with a new input value | {step * 1e6:.0f} |"]
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "cosim_residual_cost.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
