"""Checks `lsc-fmu sweep` makes before a study runs: the grid, the files, the recommendation target.

Each raises ValueError with one sentence naming the option; the command prints it and exits 2.
"""
import math
import os

from ._cli_checks import assignments, check_parent, decimal

# Names a Latin hypercube cannot sample: categories, not numbers (and `k`, the number of
# differentiations of a gallery problem; an FMU's `k` is its own, e.g. a stiffness).
_CATEGORICAL = ("method", "completion", "extrapolation", "iterations")
# Names a LinearDAE (gallery) target takes; it has no model parameters.
_DAE_NAMES = ("lam", "step", "rtol", "atol", "method", "offset", "completion", "k")
_NUMBERS = ("lam", "step", "rtol", "atol", "offset", "k", "extrapolation", "iterations")


# Names whose values are not the model's: read here, not by an FMU variable's type.
_OWN = _DAE_NAMES + ("extrapolation", "iterations", "algorithm", "exchange")


def _grid_value(name, text):
    """A --grid value: a number for the study's own numeric names, else the text as given.

    Texts of other names are read later by the target's variable types
    (`typed_grid`): a String "42" stays a text, an Integer "2.5" is refused.
    """
    if name not in _OWN:
        return text
    value = decimal(text)
    if value is not None:
        return int(value) if text.strip().lstrip("+-").isdigit() else value
    if not text or name in _NUMBERS or text[:1].isdigit() or text[:1] in "+-.":
        if name in _NUMBERS:
            raise ValueError(f"`--grid` {name}: `grid[{name!r}]` must hold real numbers; found {text!r} (str).")
        raise ValueError(f"`--grid` {name}: {text!r} is not a plain decimal number.")
    return text


def grid_of(args):
    """The grid `sweep` takes, from --grid or --lhs/--range (names given once, values plain numbers)."""
    if args.lhs is not None:
        if args.grid or not args.range:
            raise ValueError("`--lhs` takes --range NAME=LOW:HIGH inputs (and no --grid)")
        if args.seed < 0:
            raise ValueError(f"`--seed` must be a non-negative integer; found {args.seed}.")
        ranges = {}
        for name, span in assignments(args.range, "--range", "NAME=LOW:HIGH").items():
            low, sep, high = span.partition(":")
            lo, hi = decimal(low), decimal(high)
            if not sep or lo is None or hi is None:
                raise ValueError(f"`--range` {name}: expected NAME=LOW:HIGH with plain decimal numbers; "
                                 f"found {span!r}.")
            if name in _CATEGORICAL:
                raise ValueError(f"`--range` {name}: `{name}` takes categories, which a Latin hypercube cannot "
                                 "sample; use --grid.")
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"`--range` {name}: expected finite LOW < HIGH; found {span!r}.")
            ranges[name] = (lo, hi)
        return args.lhs, ranges
    if not args.grid or args.range:
        raise ValueError("give --grid NAME=V1,V2,... (or --lhs N with --range)")
    return {name: [_grid_value(name, v.strip()) for v in values.split(",")]
            for name, values in assignments(args.grid, "--grid", "NAME=V1,V2,...").items()}


def grid_names(grid):
    """The input names of a grid as `grid_of` returns it."""
    return list(grid[1] if isinstance(grid, tuple) else grid)


def check_names(grid, target):
    """Refuse a grid name the target does not take (a LinearDAE target takes no model parameters)."""
    names = list(grid[1] if isinstance(grid, tuple) else grid)
    if not isinstance(target, str):  # a gallery Problem
        unknown = [n for n in names if n not in _DAE_NAMES]
        if unknown:
            raise ValueError(f"`--grid` names {unknown} are not inputs of a gallery problem; it takes "
                             f"{', '.join(_DAE_NAMES)}.")
        if isinstance(grid, tuple) and "k" in names:
            raise ValueError("`--range` k: `k` (the number of differentiations) takes categories, which a Latin "
                             "hypercube cannot sample; use --grid.")
        return
    if target.lower().endswith(".fmu") and os.path.isfile(target):
        from fmpy import read_model_description

        variables = {v.name for v in read_model_description(target).modelVariables}
        unknown = [n for n in names if n not in ("step", "offset")
                   and {"lam": "lambda", "method": "solver"}.get(n, n) not in variables]
        if unknown:
            raise ValueError(f"`--grid` names {unknown} are not variables of {target!r} (nor step, offset).")
        return
    if target.lower().endswith((".ssp", ".ssd")) or os.path.isdir(target):
        if "step" not in names:
            raise ValueError("an SSP target needs `step` (the macro step) in --grid.")
        if "lam" in names and any(n.endswith(".lambda") for n in names):
            both = [n for n in names if n.endswith(".lambda")]
            raise ValueError(f"`lam` sets every component's lambda; with {both} too one would silently win: "
                             "give one of them.")


def check_files(args):
    """Refuse an output or plot that would overwrite the target, each other, or cannot be written."""
    import zipfile

    target = args.target
    if target.lower().endswith(".fmu") and os.path.isfile(target):
        if not zipfile.is_zipfile(target) or "modelDescription.xml" not in zipfile.ZipFile(target).namelist():
            raise ValueError(f"`target` {target!r} is not an FMU (a zip archive holding modelDescription.xml).")
    out = args.output
    if os.path.isdir(out) or out.endswith(("/", os.sep)):
        raise ValueError(f"`-o` must be a .csv or .parquet file; found the folder {out!r}.")
    if not out.lower().endswith((".csv", ".parquet")):
        raise ValueError(f"`-o` must be a .csv or .parquet file; found {out!r}.")
    check_parent(out, "-o")
    if os.path.exists(target) and os.path.exists(out) and os.path.samefile(target, out):
        raise ValueError(f"`-o` {out!r} is the target: writing the study there would destroy it.")
    if args.plot:
        plot = args.plot
        if os.path.isdir(plot):
            raise ValueError(f"`--plot` {plot!r} is a folder; give a .png file.")
        if os.path.abspath(plot) == os.path.abspath(out):
            raise ValueError(f"`--plot` {plot!r} is the output `-o`: the plot would replace the study's rows.")
        if os.path.exists(target) and os.path.exists(plot) and os.path.samefile(target, plot):
            raise ValueError(f"`--plot` {plot!r} is the target: the plot would replace it.")
        check_parent(plot, "--plot")
        folder = os.path.dirname(os.path.abspath(plot))
        if not os.path.isdir(folder):
            raise ValueError(f"`--plot` {plot!r}: the folder {folder!r} does not exist.")
    if args.recommend is not None and not (math.isfinite(args.recommend) and args.recommend > 0):
        raise ValueError(f"`--recommend` must be a positive finite error; found {args.recommend!r}.")


def check_plot(args, grid):
    """Refuse --plot for a study without lam before it runs (the plots are against lam)."""
    if args.plot and "lam" not in grid_names(grid):
        raise ValueError("`--plot` draws error and cost against lam: give lam in --grid (or --range), or leave "
                         "out --plot.")


def typed_grid(grid, target):
    """The grid with each text read by the type of the variable it sets.

    An FMU's variables convert by their declared type (Real, Integer, Boolean;
    an Enumeration keeps an item's name, a String its text); a spec's, not
    typed before it is built, become numbers where they read as one and stay
    texts otherwise (a run reads them by the type); a ``"component.variable"`` of an SSP
    scenario stays a text, read by ``cosimulate`` by the variable's type. A
    value the type cannot hold is refused naming the grid name.
    """
    if isinstance(grid, tuple) or not isinstance(target, str):
        return grid
    variables = {}
    if target.lower().endswith(".fmu") and os.path.isfile(target):
        from fmpy import read_model_description

        variables = {v.name: v for v in read_model_description(target).modelVariables}
    elif target.lower().endswith((".ssp", ".ssd")) or os.path.isdir(target):
        return grid
    typed = {}
    for name, values in grid.items():
        if name in _OWN or not all(isinstance(v, str) for v in values):
            typed[name] = values
        elif name in variables:
            typed[name] = [_typed(name, text, variables[name]) for text in values]
        else:  # a spec's variable, typed only once it is built: a number, or a text the run reads by the type
            typed[name] = [_number_or_text(name, text) for text in values]
    return typed


def _typed(name, text, variable):
    from .study._runs import enumeration_items, fmi_value

    try:
        value = fmi_value(name, text, variable.type, enumeration_items(variable))
    except TypeError as exc:
        raise ValueError(f"`--grid` {name}: {exc}") from None
    if variable.type == "Enumeration" and text.strip() in dict(enumeration_items(variable)):
        return text.strip()  # the item's name, as given
    return value


def _number_or_text(name, text):
    value = decimal(text)
    if value is not None:
        return int(value) if text.strip().lstrip("+-").isdigit() else value
    if not text or text[:1].isdigit() or text[:1] in "+-.":
        raise ValueError(f"`--grid` {name}: {text!r} is not a plain decimal number.")
    return text  # e.g. 'true' for a Boolean parameter
