"""What `lsc-fmu cosim` checks before a run and writes after it: the step control's options, the CSV, the plot."""
import math

from ._cli_checks import check_step


def write_csv(path, result):
    """The result as CSV: numbers with 17 digits, integers exact, Booleans as 0/1, Strings quoted where needed,
    Binary values as hexadecimal text."""
    import csv

    import numpy as np

    def cell(x):
        if isinstance(x, str):
            return x
        if isinstance(x, (bytes, bytearray)):
            return bytes(x).hex()
        if isinstance(x, (bool, np.bool_)) or isinstance(x, (int, np.integer)):
            return str(int(x))
        return format(float(x), ".17g")

    names = result.dtype.names
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(names)
        for row in result:
            writer.writerow([cell(row[n]) for n in names])


def check_step_control(args):
    """The step control's options: positive and finite, ``--min-step <= --step-size <= --max-step``, and only
    with ``--step-control`` (a fixed-step run would ignore them)."""
    for option in ("--rtol", "--atol", "--min-step", "--max-step"):
        value = getattr(args, option[2:].replace("-", "_"))
        check_step(value, option)
        if value is not None and option != "--rtol" and not args.step_control:
            raise ValueError(f"`{option}` bounds the step control: it needs `--step-control` (found {value!r} "
                             "without it; a fixed-step run takes --step-size).")
    low = args.min_step if args.min_step is not None else 0.0
    high = args.max_step if args.max_step is not None else math.inf
    if not low <= args.step_size <= high:
        raise ValueError(f"`--min-step` <= `--step-size` <= `--max-step` must hold; found {args.min_step!r}, "
                         f"{args.step_size!r}, {args.max_step!r}.")



def plot_result(result, path):
    """The numeric columns of ``result`` against time, as a PNG at ``path`` (Strings and Binary values are in the
    CSV only)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for n in result.dtype.names[1:]:
        if result.dtype[n].kind in "biuf":
            ax.plot(result["time"], result[n], label=n)
    ax.set_xlabel("time")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(str(path), dpi=110)
    plt.close(fig)
