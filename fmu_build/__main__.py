"""Command line ``lsc-fmu`` (also ``python -m fmu_build``): build, simulate, env, ecos, cosim, sweep.

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
  build     build an FMU from a TOML spec (pythonfmu, or native C with --native)
              lsc-fmu build examples/specs/prescribed_path.toml -o out
              lsc-fmu build examples/specs/prescribed_path.toml -o out --native --fix-parameters
  simulate  run an FMU in fmpy, write its outputs as CSV (and a PNG plot)
              lsc-fmu simulate out/PathInput.fmu --input examples/inputs/path.csv --plot -o out/run.csv
  env       print the shell exports a native (non-Python) FMI host needs, ecos on PATH
              eval "$(lsc-fmu env)" && ecos simulate --path out/PrescribedPath.fmu --stopTime 10 --stepSize 0.01
  ecos      run the ecos host shipped with ecospy, with that environment
              lsc-fmu ecos simulate --path out/PrescribedPath.fmu --stopTime 10 --stepSize 0.01
  cosim     co-simulate FMUs connected in an SSP file (or .ssd) with a fixed macro step
              lsc-fmu cosim out/path_control.ssp --stop-time 10 --step-size 0.01 -o out/result.csv --plot
  sweep     run a parameter study (lambda, steps, tolerances, parameters) on Dask
              lsc-fmu sweep gallery:prescribed_path --grid lam=0.5,1,2,4,8 --grid offset=0.01 -o out/study.csv

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
    p.add_argument("--force", action="store_true", help="replace an existing output file that is not an FMU")
    _add_native_flags(p)


def _check_build_output(output, force):
    """Refuse an output that is an existing file other than an FMU, or below a file."""
    import zipfile

    from ._cli_checks import check_parent

    check_parent(output, "-o")
    if not os.path.isfile(output):
        return
    if not output.lower().endswith(".fmu"):
        raise ValueError(f"`-o` {output!r} is an existing file; expected a folder or a .fmu file name.")
    is_fmu = zipfile.is_zipfile(output) and "modelDescription.xml" in zipfile.ZipFile(output).namelist()
    if not is_fmu and not force:
        raise ValueError(f"`-o` {output!r} exists and is not an FMU; pass --force to replace it.")


def _run_build(args):
    from .spec import SpecError
    from .targets import build_fmu

    try:
        _check_build_output(args.output, args.force)
        path = build_fmu(args.spec, args.output, method=args.method, lam=args.lam, model_name=args.name, k=args.k,
                         **_native_options(args))
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
                    "time. It is checked before the run: times finite and strictly increasing, every value a "
                    "finite number, every column an input of the FMU, every input a column or given a start "
                    "value (not both: a column and --set). Each column is fitted by the interpolating spline of degree 5 through its rows "
                    "(scipy's make_interp_spline, not-a-knot ends; degree rows - 1 below 6 rows): its j-th "
                    "derivative errs by O(spacing^(6 - j)) for a smooth signal. Every communication point, the "
                    "start included, receives the fit's value and, where the FMU takes them (native FMUs: "
                    "fmi2SetRealInputDerivatives), its derivatives; an FMU that takes none (pythonfmu, FMI 3.0) "
                    "estimates them, guessing them at the start (a note says so). A table whose fit rings "
                    "between its rows (a jump, a staircase of rounded values) is refused. --linear-input "
                    "interpolates linearly and sends values only, as fmpy does (for a table with corners or jumps).",
        epilog="example: lsc-fmu simulate out/PathInput.fmu --input examples/inputs/path.csv --step 0.01 --plot -o out/run.csv",
    )
    p.add_argument("fmu", help="path of the .fmu file")
    p.add_argument("--input", metavar="CSV", help="input signals: columns 'time' and one per FMU input")
    p.add_argument("--linear-input", action="store_true",
                   help="interpolate the input CSV linearly and send values only (fmpy's way), not the spline fit "
                        "and its derivatives")
    p.add_argument("-o", "--output", metavar="CSV",
                   help="result file, or a folder to write <model>.csv into (default: <model>.csv in the current folder)")
    p.add_argument("--plot", action="store_true", help="also plot the outputs to the result's name with .png")
    p.add_argument("--start-time", type=float, help="start time (default: the FMU's default experiment)")
    p.add_argument("--stop-time", type=float, help="stop time (default: the FMU's default experiment)")
    p.add_argument("--step", type=float, help="communication step (default: the FMU's default experiment)")
    p.add_argument("--set", metavar="NAME=VALUE", action="append", default=[],
                   help="a start value, e.g. --set lambda=10 (repeatable)")
    p.add_argument("--force", action="store_true", help="replace an existing output file that is not a result")


def _experiment(args, md):
    """(start, stop, step) from the options and the FMU's default experiment, each checked."""
    from ._cli_checks import check_span, check_step, check_time

    experiment = md.defaultExperiment
    default = (lambda name: float(getattr(experiment, name)) if experiment is not None
               and getattr(experiment, name) is not None else None)
    start = check_time(args.start_time, "--start-time")
    stop = check_time(args.stop_time, "--stop-time")
    step = check_step(args.step, "--step")
    start = start if start is not None else check_time(default("startTime"), "startTime of the FMU") or 0.0
    stop = stop if stop is not None else check_time(default("stopTime"), "stopTime of the FMU")
    if stop is None:
        stop = start + 1.0  # fmpy's default when the FMU states none
    step = step if step is not None else check_step(default("stepSize"), "stepSize of the FMU")
    check_span(start, stop, step if step is not None else (stop - start) / 500, "--stop-time", "--step")
    return start, stop, step


def _simulate_output(args, md):
    """The result file: -o, -o FOLDER/<model>.csv, or <model>.csv; checked against the inputs."""
    from ._cli_checks import check_output

    out = Path(args.output) if args.output else Path(f"{md.modelName}.csv")
    if out.is_dir():
        out = out / f"{md.modelName}.csv"
    if args.plot and out.with_suffix(".png") == out:
        raise ValueError(f"`--plot` writes the plot to the result's name with .png, which is the result "
                         f"{os.fspath(out)!r} itself; give `-o` a .csv name.")
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    for path in [out] + ([out.with_suffix(".png")] if args.plot else []):
        check_output(path, [args.fmu, args.input], "-o", args.force, columns=outputs)
    return out, outputs


def _run_simulate(args):
    import shutil
    import signal
    import tempfile

    from fmpy import extract, read_model_description, simulate_fmu

    from ._cli_checks import check_fmu_file, check_input_csv, typed_start_values

    logs, interrupted = [], []

    def logger(*args):  # keep the FMU's warnings and errors for the reason
        # FMI 2.0 calls (environment, instance, status, category, message), FMI 3.0 (environment, status,
        # category, message): the status is third from the end, the message last
        status, message = args[-3], args[-1]
        if status >= 1 and message:
            logs.append(message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message))

    def stop(signum, frame):  # Ctrl-C or SIGTERM: end the run, then clean up (the FMU may swallow the exception)
        interrupted.append(signal.Signals(signum).name)
        raise KeyboardInterrupt

    try:
        check_fmu_file(args.fmu)
        md = read_model_description(args.fmu)
        start_values = typed_start_values(args.set, md.modelVariables)
        start, stop_time, step = _experiment(args, md)
        out, outputs = _simulate_output(args, md)
        signals = None
        if args.input:
            inputs = {v.name: v.start for v in md.modelVariables if v.causality == "input"}
            signals = check_input_csv(args.input, inputs, start_values, span=(start, stop_time))
    except Exception as exc:  # fmpy raises bare Exception; report any failure as one line
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    unzipped = tempfile.mkdtemp(prefix="lsc_simulate_")  # fmpy's own extraction is left behind on a signal
    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        result = None
        if signals is not None and not args.linear_input:
            result, signals = _simulate_fitted(args, md, signals, (start, stop_time, step), start_values, outputs)
        if result is None:
            extract(args.fmu, unzipdir=unzipped)
            result = simulate_fmu(unzipped, start_time=start, stop_time=stop_time, output_interval=step,
                                  start_values=start_values, input=signals, output=outputs, logger=logger,
                                  debug_logging=True, model_description=md)
    except (Exception, KeyboardInterrupt) as exc:
        if interrupted or isinstance(exc, KeyboardInterrupt):
            print(f"lsc-fmu: error: interrupted ({interrupted[0] if interrupted else 'SIGINT'}); nothing written.",
                  file=sys.stderr)
            return 130
        reason = f" (the FMU logged: {logs[-1]})" if logs else ""
        print(f"lsc-fmu: error: {args.fmu}: {exc}{reason}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        shutil.rmtree(unzipped, ignore_errors=True)
    _write_result(out, result)
    print(out)
    if args.plot:
        print(_plot_simulation(out, result, outputs, md))
    reached = result["time"][-1] if len(result) else start
    tolerance = 1e-6 * (step if step is not None else (stop_time - start) / 500)
    if not reached >= stop_time - tolerance:  # relative to the step: |stop| may dwarf the horizon
        reason = logs[-1] if logs else "the FMU gave no reason"
        print(f"lsc-fmu: error: the run stopped at t = {float(reached):g} before the stop time {stop_time:g}: {reason}",
              file=sys.stderr)
        return 1
    return 0


def _simulate_fitted(args, md, signals, run, start_values, outputs):
    """The input table's smooth fit: (result, None) for a Co-Simulation FMU, run with the fit's values and
    derivatives from the start; (None, the fit's values at every output point) for a Model Exchange one."""
    import numpy as np

    from ._input_tables import fit_inputs, simulate_with_inputs

    start, stop_time, step = run
    fit = fit_inputs(signals)
    fmi3 = not str(md.fmiVersion).startswith("2.")
    if md.coSimulation is None or fmi3:  # no derivatives can be sent; fmpy runs it with the fit's values
        grid = np.append(np.arange(start, stop_time, step if step is not None else (stop_time - start) / 500),
                         stop_time)
        what = ("an FMI 3.0 FMU cannot receive input derivatives (FMI 3.0 has no fmi3SetRealInputDerivatives)"
                if fmi3 else "a Model Exchange FMU cannot receive input derivatives")
        print(f"lsc-fmu: note: {what}: the fit's values at every output point; the FMU estimates the derivatives, "
              "guessing them at the start", file=sys.stderr)
        return None, fit.sample(grid)
    notes = []
    result = simulate_with_inputs(args.fmu, fit, start_time=start, stop_time=stop_time, step=step,
                                  start_values=start_values, output=outputs, notes=notes)
    for note in notes:
        if "values only" in note:
            print(f"lsc-fmu: note: {note}", file=sys.stderr)
    if any("values only" in note for note in notes):
        print("lsc-fmu: note: a native FMU (lsc-fmu build --native) takes the input derivatives", file=sys.stderr)
    return result, None


def _write_result(out, result):
    """fmpy's CSV, written to a temporary file then renamed (no half-written result)."""
    from fmpy.util import write_csv

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp{os.getpid()}")
    write_csv(tmp, result)
    os.replace(tmp, out)


def _plot_simulation(out, result, outputs, md):
    import matplotlib.pyplot as plt

    from ._cli_plots import simulation_figure

    fig = simulation_figure(result, outputs, md, f"{md.modelName} in fmpy")
    png = out.with_suffix(".png")
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return png


def _add_env(sub):
    sub.add_parser(
        "env", help="print the shell exports a native (non-Python) FMI host needs",
        description="Print LD_PRELOAD, PYTHONHOME and PYTHONPATH for a native FMI host that loads these "
                    "pythonfmu FMUs, and put the ecos binary of ecospy (made executable) on PATH.",
        epilog='example: eval "$(lsc-fmu env)" && ecos simulate --path out/PrescribedPath.fmu --stopTime 10 --stepSize 0.01',
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


def _add_native_flags(build):
    """``--native`` (generated C, FMI 2.0 CS + ME, no Python in the host) and ``--fix-parameters``."""
    build.add_argument("--native", action="store_true",
                       help="build a native C FMU (Co-Simulation and Model Exchange; constant A and B, or "
                            "time-varying ones tabulated over the experiment)")
    build.add_argument("--fix-parameters", action="store_true",
                       help="with --native: fix tunable parameters that enter A or B at their spec values")
    build.add_argument("--fmi-version", type=int, choices=[2, 3], default=2,
                       help="with --native: FMI 2.0 (default) or FMI 3.0")


def _native_options(args):
    if args.fix_parameters and not args.native:
        raise ValueError("`--fix-parameters` applies to --native builds only.")
    if args.fmi_version != 2 and not args.native:
        raise ValueError("`--fmi-version 3` applies to --native builds only.")
    return {"target": "native", "fix_parameters": args.fix_parameters, "fmi_version": args.fmi_version} if args.native else {}


def _add_sweep(sub):
    sweep = sub.add_parser(
        "sweep", help="run a parameter study (lam, steps, tolerances, parameters) on Dask",
        description="Run one simulation per point of a grid (or a Latin hypercube sample) in Dask worker "
                    "processes and write one row per run: the inputs, success, message, error against the "
                    "reference, residuals, run time, steps. Needs the sweep extra (pip install -e \".[sweep]\"). "
                    "An existing output of the same study is resumed; the study's identity is kept in "
                    "OUTPUT.study.json and a file of another study is refused. Exits 1 when any run failed "
                    "(with --allow-failures: when every run failed) or no run reaches the --recommend target, "
                    "2 when the study is refused before running, 130 on Ctrl-C (the finished rows stay; the same "
                    "command resumes).",
        epilog="example: lsc-fmu sweep out/PrescribedPath.fmu --grid lam=0.5,1,2,4,8 --grid offset=0.01 --t-span 0 4 "
               "--error-from 4 --reference gallery:prescribed_path -o out/study.csv --plot out/study.png "
               "--recommend 1e-5")
    sweep.add_argument("target", help="an .fmu, a .toml spec, an SSP scenario, or gallery:NAME (an lsc.gallery problem)")
    sweep.add_argument("--grid", action="append", default=[], metavar="NAME=V1,V2,...",
                       help="values of one input (repeat: every combination is run)")
    sweep.add_argument("--lhs", type=int, metavar="N", help="Latin hypercube sample of N points of the --range inputs")
    sweep.add_argument("--range", action="append", default=[], metavar="NAME=LOW:HIGH", help="range of one input (with --lhs)")
    sweep.add_argument("-o", "--output", required=True, help="result file (.csv or .parquet); an existing one is resumed")
    sweep.add_argument("--reference", default=None,
                       help="'exact' (gallery targets; their default), 'tightest' (the run at the smallest step and "
                            "tolerances and the largest lam of each group; the default otherwise) or gallery:NAME "
                            "(the exact solution of an lsc.gallery problem, for an FMU of the same model)")
    sweep.add_argument("--t-span", type=float, nargs=2, metavar=("T0", "T1"), help="horizon (default: the target's)")
    sweep.add_argument("--error-from", type=float, help="the error counts from this time on")
    sweep.add_argument("--scheduler", help="address of an existing Dask scheduler, or 'serial' (default: an embedded cluster)")
    sweep.add_argument("--workers", type=int, default=2, help="worker processes of the embedded cluster (default: 2)")
    sweep.add_argument("--seed", type=int, default=0, help="seed of the Latin hypercube")
    sweep.add_argument("--plot", help="write the summary plots to this PNG")
    sweep.add_argument("--recommend", type=float, metavar="ERROR", help="print the cheapest point reaching this error")
    sweep.add_argument("--on", default="error", choices=["error", "residual_final"],
                       help="the column --recommend holds to ERROR: the error against the reference (default) or the "
                            "final constraint residual")
    sweep.add_argument("--cost", default="run_time", choices=["run_time", "steps"], help="cost the recommendation minimizes")
    sweep.add_argument("--allow-failures", action="store_true",
                       help="exit 0 when some runs fail (default: exit 1 when any run failed)")
    sweep.add_argument("--no-progress", action="store_true", help="no progress bar")
    sweep.add_argument("--timeout", type=float, metavar="SECONDS",
                       help="end a run that takes longer (its worker is restarted; recorded as failed)")


def _run_sweep(args):
    """``lsc-fmu sweep``: run a study, write it, optionally plot and recommend."""
    from .study import plot_study, recommend, sweep

    from ._cli_sweep import check_files, check_names, check_plot, grid_names, grid_of, typed_grid

    try:
        grid = grid_of(args)
        check_files(args)
        check_plot(args, grid)
        target = _gallery(args.target) if args.target.startswith("gallery:") else args.target
        reference = args.reference
        if reference is not None and reference.startswith("gallery:"):
            reference = _gallery(reference)
        elif reference not in (None, "exact", "tightest"):
            raise ValueError(f"`--reference` must be 'exact', 'tightest' or gallery:NAME; found {reference!r}.")
        check_names(grid, target)
        grid = typed_grid(grid, target)
        df = sweep(target, grid, reference=reference, scheduler=args.scheduler, progress=not args.no_progress,
                   output=args.output, t_span=args.t_span, error_from=args.error_from, n_workers=args.workers,
                   seed=args.seed, timeout=args.timeout)
    except (ValueError, TypeError, OSError, ImportError) as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # the rows written so far stay; the study's files say how to go on
        print(f"lsc-fmu: interrupted; the finished runs are in {args.output}: run the same command again to "
              "compute only the missing ones.", file=sys.stderr)
        return 130
    failed = df[~df["success"]]
    print(f"{len(df)} runs ({len(failed)} failed) written to {args.output}")
    if args.plot:
        print(plot_study(df, args.plot, cost=args.cost))
    status = 0
    if args.recommend is not None:
        choice = recommend(df, args.recommend, cost=args.cost, on=args.on)
        print(choice)
        if choice.row is None:  # the command was asked for a point and has none
            print(f"lsc-fmu: error: no run reaches {args.on} <= {args.recommend:g}; widen the grid (larger lam, "
                  "smaller step or tolerances).", file=sys.stderr)
            status = 1
    if len(failed) and (len(failed) == len(df) or not args.allow_failures):
        run = failed.index[0]
        point = ", ".join(f"{k}={v}" for k, v in failed.iloc[0].items() if k in grid_names(grid))
        first = f"run {run} ({point}): {failed['message'].iloc[0]}"
        if len(failed) == len(df):
            print(f"lsc-fmu: error: every run of the study failed; the first: {first}", file=sys.stderr)
        else:
            print(f"lsc-fmu: error: {len(failed)} of {len(df)} runs failed (the rows say why; --allow-failures "
                  f"when some may fail); the first: {first}", file=sys.stderr)
        return 1
    return status


def _gallery(text):
    """The lsc.gallery problem a ``gallery:NAME`` names."""
    import lsc

    name = text.split(":", 1)[1]
    if name not in lsc.gallery.__all__ or name in ("Problem", "StateSpace"):
        raise ValueError(f"gallery:NAME must name an lsc.gallery problem; found {name!r}")
    return getattr(lsc.gallery, name)()


def _add_cosim(sub):
    cosim = sub.add_parser(
        "cosim", help="co-simulate FMUs connected by an SSP file (.ssp/.ssd)",
        description="Co-simulate the FMUs (FMI 2.0 and 3.0 Co-Simulation) of an SSP system (an .ssp archive or a "
                    "SystemStructure.ssd) with a fixed macro step in fmpy, and write the recorded variables as CSV (columns 'time' and "
                    "'component.variable'). A run that stops early writes what it computed and exits 1.",
        epilog="example: lsc-fmu cosim out/path_control.ssp --stop-time 10 --step-size 0.01 -o out/result.csv --plot")
    cosim.add_argument("system", help="the .ssp or .ssd file")
    cosim.add_argument("--stop-time", type=float, required=True, help="end time")
    cosim.add_argument("--step-size", type=float, required=True, help="macro step")
    cosim.add_argument("--algorithm", choices=["gauss-seidel", "jacobi"], default="gauss-seidel")
    cosim.add_argument("--extrapolation", type=int, choices=[0, 1, 2], default=0, help="degree of the input polynomial")
    cosim.add_argument("--iterations", type=int, default=0, help="step repeats with rollback (0: explicit)")
    cosim.add_argument("--step-control", action="store_true", help="vary the macro step (--step-size: the first)")
    cosim.add_argument("--rtol", type=float, default=1e-4, help="relative tolerance of the step control")
    cosim.add_argument("--atol", type=float, help="absolute tolerance of the step control (default: --rtol)")
    cosim.add_argument("--min-step", type=float,
                       help="smallest macro step of the step control (default: 1e-12 times --step-size)")
    cosim.add_argument("--max-step", type=float,
                       help="largest macro step of the step control (default: the time span); below the "
                            "shortest event of the sources, which no master sees inside a step")
    cosim.add_argument("--lambda-per-step", type=float, help="set each DAE FMU's lambda to this / H")
    cosim.add_argument("--no-early-return", action="store_true",
                       help="instantiate FMI 3.0 FMUs without early return (events handled inside the step)")
    cosim.add_argument("--start", action="append", default=[], metavar="COMP.VAR=VALUE", help="a start value (repeatable)")
    cosim.add_argument("--output", action="append", metavar="COMP.VAR", help="a variable to record (repeatable)")
    cosim.add_argument("-o", "--result", default="result.csv", help="CSV file to write (default: result.csv)")
    cosim.add_argument("--plot", action="store_true", help="also write a PNG next to the CSV")
    cosim.add_argument("--force", action="store_true", help="replace an existing output file that is not a result")


def _run_cosim(args):
    """``lsc-fmu cosim``: run fmu_build.cosimulate and write CSV (and a plot)."""
    import warnings
    from pathlib import Path

    from ._cli_checks import assignments, check_output, check_span, check_step, check_system_file, check_time
    from ._cli_cosim import check_step_control, plot_result, write_csv
    from .cosim import cosimulate

    try:
        check_span(0.0, check_time(args.stop_time, "--stop-time"), check_step(args.step_size, "--step-size"),
                   "--stop-time", "--step-size")
        check_step_control(args)
        outputs = [Path(args.result)] + ([Path(args.result).with_suffix(".png")] if args.plot else [])
        if args.plot and outputs[1] == outputs[0]:
            raise ValueError(f"`--plot` writes the plot to the result's name with .png, which is the result "
                             f"{args.result!r} itself; give `-o` a .csv name.")
        for path in outputs:
            check_output(path, [args.system], "-o", args.force, columns=args.output)
        check_system_file(args.system)
        if not Path(args.result).resolve().parent.is_dir():
            raise ValueError(f"`-o` {args.result}: the folder {str(Path(args.result).parent)!r} does not exist.")
        # texts: cosimulate reads each by its variable's type (a String "42" stays a string)
        start = assignments(args.start, "--start", "COMP.VAR=VALUE")
    except ValueError as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            result = cosimulate(args.system, args.stop_time, args.step_size, algorithm=args.algorithm,
                                extrapolation=args.extrapolation, iterations=args.iterations, start_values=start,
                                output=args.output, step_control=args.step_control,
                                rtol=args.rtol if args.step_control else 1e-10, lambda_per_step=args.lambda_per_step,
                                early_return=not args.no_early_return,
                                atol=args.atol, min_step=args.min_step, max_step=args.max_step)
    except (ValueError, TypeError, OSError) as exc:
        print(f"lsc-fmu: error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # a corrupt archive or description: BadZipFile, XMLSyntaxError, ...
        print(f"lsc-fmu: error: could not read the system {args.system!r} ({type(exc).__name__}: {exc}); "
              "expected an SSP archive (.ssp) or a SystemStructure.ssd (see docs/cosimulation.md).", file=sys.stderr)
        return 2
    tmp = Path(args.result).with_name(f".{Path(args.result).name}.tmp{os.getpid()}")
    write_csv(tmp, result)
    os.replace(tmp, args.result)
    if args.plot:
        plot_result(result, Path(args.result).with_suffix(".png"))
    print(args.result)
    if not result.success:
        print(f"lsc-fmu: co-simulation stopped: {result.message}", file=sys.stderr)
        return 1
    return 0


COMMANDS = {
    "build": (_add_build, _run_build),
    "simulate": (_add_simulate, _run_simulate),
    "env": (_add_env, _run_env),
    "ecos": (_add_ecos, _run_ecos),
    "cosim": (_add_cosim, _run_cosim),
    "sweep": (_add_sweep, _run_sweep),
}


def parser():
    """The argument parser of ``lsc-fmu``: one subcommand per entry of COMMANDS."""
    main_parser = argparse.ArgumentParser(prog="lsc-fmu", description=DESCRIPTION,
                                          formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = main_parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add, _ in COMMANDS.values():
        add(sub)
    return main_parser


def main(argv=None):
    """Run ``lsc-fmu`` with `argv` (default: the command line); return the exit status.

    ``--markdown`` alone prints the command-line reference (docs/cli.md).
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv == ["--markdown"]:
        from ._cli_docs import markdown

        print(markdown(parser()), end="")
        return 0
    args = parser().parse_args(argv)
    return COMMANDS[args.command][1](args)


if __name__ == "__main__":
    sys.exit(main())
