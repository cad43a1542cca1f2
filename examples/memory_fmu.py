"""Memory per FMU instance: RSS growth over instantiate/free cycles, ours against a do-nothing pythonfmu FMU.

Run: ``python examples/memory_fmu.py [cycles]``. Each FMU runs in its own fresh process
(fmpy's FMU2Slave): 20 warm-up cycles, then `cycles` cycles of instantiate, setupExperiment,
initialization, 10 doSteps, terminate, freeInstance; the growth of the resident set size over
those cycles is divided by their number. Both FMUs are measured in one run, side by side.
"""
import json
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).parent

_NOTHING = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Nothing(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.x = 0.0
        self.register_variable(Real("x", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        return True
'''

_CYCLES = '''
import gc, json, sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

def rss():
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmRSS"))

path, cycles, collect = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
md = read_model_description(path)
unzipped = extract(path)
fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="m")

def cycle():
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    for k in range(10):
        fmu.doStep(0.01 * k, 0.01)
    fmu.terminate()
    fmu.fmi2FreeInstance(fmu.component)
    if collect:
        gc.collect()

for _ in range(20):
    cycle()
start = rss()
for _ in range(cycles):
    cycle()
print(json.dumps({"kB_per_instance": (rss() - start) / cycles}))
'''


def measure(fmu, cycles, collect=False):
    out = subprocess.run([sys.executable, "-c", _CYCLES, str(fmu), str(cycles), "1" if collect else "0"],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])["kB_per_instance"]


def main(cycles=200):
    from pythonfmu.builder import FmuBuilder

    from fmu_build import build_fmu

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        script = tmp / "Nothing.py"
        script.write_text(_NOTHING)
        nothing = FmuBuilder.build_FMU(script, dest=tmp / "nothing")
        ours = build_fmu(HERE / "specs" / "prescribed_path.toml", tmp / "ours")
        for label, fmu in (("do-nothing pythonfmu FMU", nothing), ("PrescribedPath (lsc)", ours)):
            print(f"{label:28s} {measure(fmu, cycles):6.1f} kB per instance "
                  f"({measure(fmu, cycles, collect=True):6.1f} with gc.collect() after each freeInstance)")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
