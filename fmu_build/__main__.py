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
    args = parser.parse_args(argv)

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


if __name__ == "__main__":
    sys.exit(main())
