"""Command line ``lsc-fmu`` (also ``python -m fmu_build``): build, simulate, env, ecos.

Each subcommand is one pair of functions: ``_add_<name>(sub)`` declares its
arguments and ``_run_<name>(args)`` runs it and returns the exit status.
"""
import argparse
import os
import subprocess
import sys
from pathlib import Path

DESCRIPTION = """\
Build FMI 2.0 Co-Simulation FMUs of lsc completions and run them.

commands:
  build     build an FMU from a TOML spec
              lsc-fmu build examples/specs/prescribed_path.toml -o out
  simulate  run an FMU in fmpy, write its outputs as CSV (and a PNG plot)
              lsc-fmu simulate out/PathInput.fmu --input path.csv --plot -o out/run.csv
  env       print the shell exports a native (non-Python) FMI host needs, ecos on PATH
              eval "$(lsc-fmu env)" && ecos simulate --path out/PrescribedPath.fmu
  ecos      run the ecos host shipped with ecospy, with that environment
              lsc-fmu ecos simulate --path out/PrescribedPath.fmu --stopTime 10

Run `lsc-fmu COMMAND --help` for the options of one command.
"""


def _add_build(sub):
    p = sub.add_parser(
        "build", help="build an FMU from a TOML spec",
        description="Build an FMI 2.0 Co-Simulation FMU from a TOML spec. The options override the "
                    "spec's [completion] table.",
        epilog="example: lsc-fmu build examples/specs/prescribed_path.toml -o out --method alternative --lam 5",
    )
    p.add_argument("spec", help="path of the TOML spec")
    p.add_argument("-o", "--output", default=".", help="folder (or .fmu file) to write (default: .)")
    p.add_argument("--method", choices=["standard", "stabilized", "alternative"],
                   help="completion method (default: the spec's, else 'alternative')")
    p.add_argument("--lam", type=float, help="rate lambda > 0 at which the extra solutions decay (stabilized, alternative); "
                                             "it stays a tunable FMU parameter named 'lambda'")
    p.add_argument("--k", type=int, help="number of differentiations (default: decided from the index)")
    p.add_argument("--name", help="model name (default: the spec's)")


def _run_build(args):
    from ._build import build_fmu
    from ._spec import SpecError

    try:
        path = build_fmu(args.spec, args.output, method=args.method, lam=args.lam, model_name=args.name, k=args.k)
    except (SpecError, ValueError, TypeError, OSError) as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    print(path)
    return 0


def _add_simulate(sub):
    p = sub.add_parser(
        "simulate", help="run an FMU in fmpy and write its outputs as CSV (and a PNG)",
        description="Simulate an FMU in fmpy over its default experiment (or --stop-time) and write every "
                    "output to a CSV file. An input CSV has a header row 'time,<input>,...' and one row per "
                    "time; fmpy interpolates it linearly.",
        epilog="example: lsc-fmu simulate out/PathInput.fmu --input path.csv --step 0.01 --plot -o out/run.csv",
    )
    p.add_argument("fmu", help="path of the .fmu file")
    p.add_argument("--input", metavar="CSV", help="input signals: columns 'time' and one per FMU input")
    p.add_argument("-o", "--output", metavar="CSV", help="result file (default: <model>.csv in the current folder)")
    p.add_argument("--plot", action="store_true", help="also plot the outputs to the result's name with .png")
    p.add_argument("--start-time", type=float, help="start time (default: the FMU's default experiment)")
    p.add_argument("--stop-time", type=float, help="stop time (default: the FMU's default experiment)")
    p.add_argument("--step", type=float, help="communication step (default: the FMU's default experiment)")
    p.add_argument("--set", metavar="NAME=VALUE", action="append", default=[],
                   help="a start value, e.g. --set lambda=10 (repeatable)")


def _read_input_csv(path):
    import numpy as np

    data = np.genfromtxt(path, delimiter=",", names=True, dtype=float, deletechars="")
    if data.dtype.names is None or data.dtype.names[0] != "time":
        raise ValueError(f"`--input` {path}: the first column must be 'time', found {data.dtype.names}")
    return np.atleast_1d(data)


def _run_simulate(args):
    import numpy as np
    from fmpy import read_model_description, simulate_fmu
    from fmpy.util import write_csv

    try:
        start = {}
        for item in args.set:
            name, sep, value = item.partition("=")
            if not sep:
                raise ValueError(f"`--set` expects NAME=VALUE, found {item!r}")
            start[name.strip()] = float(value)
        signals = _read_input_csv(args.input) if args.input else None
        md = read_model_description(args.fmu)
        outputs = [v.name for v in md.modelVariables if v.causality == "output"]
        step = args.step if args.step is not None else (float(md.defaultExperiment.stepSize)
                                                        if md.defaultExperiment and md.defaultExperiment.stepSize else None)
        result = simulate_fmu(args.fmu, start_time=args.start_time, stop_time=args.stop_time, output_interval=step,
                              start_values=start, input=signals, output=outputs)
    except Exception as exc:  # fmpy raises bare Exception; report any failure as one line
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.output) if args.output else Path(f"{md.modelName}.csv")
    out.parent.mkdir(parents=True, exist_ok=True)
    write_csv(out, result)
    print(out)
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(len(outputs), 1, sharex=True, figsize=(7, 1.6 * len(outputs) + 1), squeeze=False)
        for ax, name in zip(axes[:, 0], outputs):
            ax.plot(result["time"], result[name])
            ax.set_ylabel(name)
            if name == "constraint_residual" and np.all(result[name] > 0):
                ax.set_yscale("log")
        axes[-1, 0].set_xlabel("time")
        fig.suptitle(f"{md.modelName} in fmpy")
        fig.tight_layout()
        png = out.with_suffix(".png")
        fig.savefig(png, dpi=100)
        plt.close(fig)
        print(png)
    return 0


def _add_env(sub):
    sub.add_parser(
        "env", help="print the shell exports a native (non-Python) FMI host needs",
        description="Print LD_PRELOAD, PYTHONHOME and PYTHONPATH for a native FMI host that loads these "
                    "pythonfmu FMUs, and put the ecos binary of ecospy (made executable) on PATH.",
        epilog='example: eval "$(lsc-fmu env)" && ecos simulate --path out/PrescribedPath.fmu --stopTime 10',
    )


def _run_env(args):
    from ._host import ecos_executable, native_host_env

    try:
        env = native_host_env({})
    except FileNotFoundError as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    for key in ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH"):
        print(f"export {key}='{env[key]}'")
    try:
        exe = ecos_executable()
    except FileNotFoundError as exc:
        print(f"lsc-fmu: note: {exc}", file=sys.stderr)
    else:
        print(f"export PATH='{exe.parent}':\"$PATH\"")
    return 0


def _add_ecos(sub):
    p = sub.add_parser(
        "ecos", help="run the ecos host shipped with ecospy, with the environment of `env`",
        description="Run ecospy's ecos binary (made executable) with LD_PRELOAD, PYTHONHOME and PYTHONPATH "
                    "set; every argument after 'ecos' goes to ecos.",
        epilog="example: lsc-fmu ecos simulate --path out/PrescribedPath.fmu --stopTime 10 --stepSize 0.01",
    )
    p.add_argument("ecos_args", nargs=argparse.REMAINDER, help="arguments for ecos (e.g. simulate --path X.fmu)")


def _run_ecos(args):
    from ._host import ecos_executable, native_host_env

    try:
        exe = ecos_executable()
        env = native_host_env()
    except FileNotFoundError as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    env["PATH"] = os.pathsep.join([str(exe.parent), env.get("PATH", "")])
    return subprocess.run([str(exe), *args.ecos_args], env=env).returncode


COMMANDS = {
    "build": (_add_build, _run_build),
    "simulate": (_add_simulate, _run_simulate),
    "env": (_add_env, _run_env),
    "ecos": (_add_ecos, _run_ecos),
}


def main(argv=None):
    parser = argparse.ArgumentParser(prog="lsc-fmu", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add, _ in COMMANDS.values():
        add(sub)
    args = parser.parse_args(argv)
    return COMMANDS[args.command][1](args)


if __name__ == "__main__":
    sys.exit(main())
