"""Run a built FMU in libcosimpy (Open Simulation Platform) and report JSON: used by test_fmu.py.

Reads {"fmu", "dt", "steps", "outputs", "initial": {name: value}, "override_at": {"i": {name: value}}}
from stdin; prints {"time", "values"}. Runs in its own process (see fmu_runner.py).
"""
import json
import sys


def main():
    sc = json.load(sys.stdin)
    from libcosimpy.CosimEnums import CosimVariableType  # noqa: F401
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)  # FMI Library floods stdout otherwise
    dt_ns = int(round(sc["dt"] * 1e9))
    execution = CosimExecution.from_step_size(step_size=dt_ns)
    slave = execution.add_local_slave(CosimLocalSlave(fmu_path=sc["fmu"], instance_name="lsc"))
    refs = {v.name.decode(): v.reference for v in execution.slave_variables(slave_index=slave)}
    for name, value in sc.get("initial", {}).items():
        if isinstance(value, int) and not isinstance(value, bool) and name in ("method", "solver"):
            execution.integer_initial_value(slave, refs[name], value)
        else:
            execution.real_initial_value(slave, refs[name], float(value))
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    manipulator = CosimManipulator.create_override()
    execution.add_manipulator(manipulator)
    outputs = sc["outputs"]
    vrs = [refs[n] for n in outputs]
    times, values = [], []
    for i in range(sc["steps"]):
        if str(i) in sc.get("override_at", {}):
            for name, value in sc["override_at"][str(i)].items():
                manipulator.slave_real_values(slave, [refs[name]], [float(value)])
        execution.step()
        times.append((i + 1) * sc["dt"])
        values.append(observer.last_real_values(slave, vrs))
    print(json.dumps({"time": times, "values": {n: [row[j] for row in values] for j, n in enumerate(outputs)}}), flush=True)


if __name__ == "__main__":
    main()
