"""Command line: ``lsc-fmu build SPEC.toml -o DIR`` (also ``python -m fmu_build``)."""
import argparse
import sys


def main(argv=None):
    parser = argparse.ArgumentParser(prog="lsc-fmu", description="Build FMI 2.0 Co-Simulation FMUs of lsc completions.")
    sub = parser.add_subparsers(dest="command", required=True)
    build = sub.add_parser("build", help="build an FMU from a TOML spec")
    build.add_argument("spec", help="path of the TOML spec")
    build.add_argument("-o", "--output", default=".", help="folder (or .fmu file) to write (default: .)")
    build.add_argument("--method", choices=["standard", "stabilized", "alternative"], help="override the completion method")
    build.add_argument("--lam", type=float, help="override the stabilization rate")
    build.add_argument("--name", help="override the model name")
    sub.add_parser("env", help="print the shell exports a native (non-Python) FMI host needs")
    _add_cosim_parser(sub)
    args = parser.parse_args(argv)

    if args.command == "cosim":
        return _cosim(args)

    if args.command == "env":
        from ._host import native_host_env

        env = native_host_env({})
        for key in ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH"):
            print(f"export {key}='{env[key]}'")
        return 0

    from ._build import build_fmu
    from ._spec import SpecError

    try:
        path = build_fmu(args.spec, args.output, method=args.method, lam=args.lam, model_name=args.name)
    except (SpecError, ValueError, TypeError, OSError) as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    print(path)
    return 0


def _add_cosim_parser(sub):
    cosim = sub.add_parser("cosim", help="co-simulate FMUs connected by an SSP file (.ssp/.ssd)")
    cosim.add_argument("system", help="the .ssp or .ssd file")
    cosim.add_argument("--stop-time", type=float, required=True, help="end time")
    cosim.add_argument("--step-size", type=float, required=True, help="macro step")
    cosim.add_argument("--algorithm", choices=["gauss-seidel", "jacobi"], default="gauss-seidel")
    cosim.add_argument("--extrapolation", type=int, choices=[0, 1, 2], default=0, help="degree of the input polynomial")
    cosim.add_argument("--iterations", type=int, default=0, help="step repeats with rollback (0: explicit)")
    cosim.add_argument("--start", action="append", default=[], metavar="COMP.VAR=VALUE", help="a start value (repeatable)")
    cosim.add_argument("--output", action="append", metavar="COMP.VAR", help="a variable to record (repeatable)")
    cosim.add_argument("-o", "--result", default="result.csv", help="CSV file to write (default: result.csv)")
    cosim.add_argument("--plot", action="store_true", help="also write a PNG next to the CSV")


def _cosim(args):
    """``lsc-fmu cosim``: run fmu_build.cosimulate and write CSV (and a plot)."""
    import warnings
    from pathlib import Path

    import numpy as np

    from .cosim import cosimulate

    try:
        start = {}
        for item in args.start:
            name, eq, value = item.partition("=")
            if not eq:
                raise ValueError(f"`--start` must be COMP.VAR=VALUE; found {item!r}.")
            start[name.strip()] = float(value)
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            result = cosimulate(args.system, args.stop_time, args.step_size, algorithm=args.algorithm,
                                extrapolation=args.extrapolation, iterations=args.iterations, start_values=start,
                                output=args.output)
    except (ValueError, TypeError, OSError) as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    names = result.dtype.names
    np.savetxt(args.result, np.column_stack([result[n] for n in names]) if len(result) else np.zeros((0, len(names))),
               delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4))
        for n in names[1:]:
            ax.plot(result["time"], result[n], label=n)
        ax.set_xlabel("time")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(str(Path(args.result).with_suffix(".png")), dpi=110)
    print(args.result)
    if not result.success:
        print(f"lsc-fmu: co-simulation stopped: {result.message}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
