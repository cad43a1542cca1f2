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
    _add_native_flags(build)
    sub.add_parser("env", help="print the shell exports a native (non-Python) FMI host needs")
    _add_sweep_parser(sub)
    _add_cosim_parser(sub)
    args = parser.parse_args(argv)

    if args.command == "sweep":
        return sweep_command(args)
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
        path = build_fmu(args.spec, args.output, method=args.method, lam=args.lam, model_name=args.name,
                         **_native_options(args))
    except (SpecError, ValueError, TypeError, OSError) as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    print(path)
    return 0


def _add_sweep_parser(sub):
    sweep = sub.add_parser("sweep", help="run a parameter study (lam, steps, tolerances, parameters) on Dask",
                           description="Run one simulation per point of a grid on Dask and write one row per run.")
    sweep.add_argument("target", help="an .fmu, a .toml spec, an SSP scenario, or gallery:NAME (an lsc.gallery problem)")
    sweep.add_argument("--grid", action="append", default=[], metavar="NAME=V1,V2,...",
                       help="values of one input (repeat: every combination is run)")
    sweep.add_argument("--lhs", type=int, metavar="N", help="Latin hypercube sample of N points of the --range inputs")
    sweep.add_argument("--range", action="append", default=[], metavar="NAME=LOW:HIGH", help="range of one input (with --lhs)")
    sweep.add_argument("-o", "--output", required=True, help="result file (.csv or .parquet); an existing one is resumed")
    sweep.add_argument("--reference", default=None, help="'exact' (gallery targets), 'tightest' (default otherwise) or 'monolithic'")
    sweep.add_argument("--t-span", type=float, nargs=2, metavar=("T0", "T1"), help="horizon (default: the target's)")
    sweep.add_argument("--error-from", type=float, help="the error counts from this time on")
    sweep.add_argument("--scheduler", help="address of an existing Dask scheduler, or 'serial' (default: an embedded cluster)")
    sweep.add_argument("--workers", type=int, default=2, help="worker processes of the embedded cluster (default: 2)")
    sweep.add_argument("--seed", type=int, default=0, help="seed of the Latin hypercube")
    sweep.add_argument("--plot", help="write the summary plots to this PNG")
    sweep.add_argument("--recommend", type=float, metavar="ERROR", help="print the cheapest point reaching this error")
    sweep.add_argument("--cost", default="run_time", choices=["run_time", "steps"], help="cost the recommendation minimizes")
    sweep.add_argument("--no-progress", action="store_true", help="no progress bar")


def _value(text):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def sweep_command(args):
    """``lsc-fmu sweep``: run a study, write it, optionally plot and recommend."""
    from .study import plot_study, recommend, sweep

    try:
        if args.lhs is not None:
            if args.grid or not args.range:
                raise ValueError("--lhs takes --range NAME=LOW:HIGH inputs (and no --grid)")
            ranges = {}
            for item in args.range:
                name, _, span = item.partition("=")
                low, _, high = span.partition(":")
                ranges[name.strip()] = (float(low), float(high))
            grid = (args.lhs, ranges)
        else:
            if not args.grid or args.range:
                raise ValueError("give --grid NAME=V1,V2,... (or --lhs N with --range)")
            grid = {}
            for item in args.grid:
                name, sep, values = item.partition("=")
                if not sep or not values:
                    raise ValueError(f"--grid must read NAME=V1,V2,...; found {item!r}")
                grid[name.strip()] = [_value(v.strip()) for v in values.split(",")]
        target = args.target
        if target.startswith("gallery:"):
            import lsc

            name = target.split(":", 1)[1]
            if name not in lsc.gallery.__all__ or name in ("Problem", "StateSpace"):
                raise ValueError(f"gallery:NAME must name an lsc.gallery problem; found {name!r}")
            target = getattr(lsc.gallery, name)()
        df = sweep(target, grid, reference=args.reference, scheduler=args.scheduler, progress=not args.no_progress,
                   output=args.output, t_span=args.t_span, error_from=args.error_from, n_workers=args.workers,
                   seed=args.seed)
    except (ValueError, TypeError, OSError, ImportError, NotImplementedError) as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    failed = int((~df["success"]).sum())
    print(f"{len(df)} runs ({failed} failed) written to {args.output}")
    if args.plot:
        print(plot_study(df, args.plot, cost=args.cost))
    if args.recommend is not None:
        print(recommend(df, args.recommend, cost=args.cost))
    return 0

def _add_native_flags(build):
    """``--native`` (generated C, FMI 2.0 CS + ME, no Python in the host) and ``--fix-parameters``."""
    build.add_argument("--native", action="store_true",
                       help="build a native C FMU (Co-Simulation and Model Exchange; constant A and B only)")
    build.add_argument("--fix-parameters", action="store_true",
                       help="with --native: fix tunable parameters that enter A or B at their spec values")


def _native_options(args):
    if args.fix_parameters and not args.native:
        raise ValueError("`--fix-parameters` applies to --native builds only.")
    return {"target": "native", "fix_parameters": args.fix_parameters} if args.native else {}


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
