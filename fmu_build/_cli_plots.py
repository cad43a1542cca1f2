"""The plots of the command line: axes by the values they show, labels with the model's units."""
import numpy as np

# A positive series spanning more than this ratio is drawn on a log axis (two decades).
DECADES = 100.0


def axis_scale(values):
    """'log' for values that are never negative and whose positive part spans decades, else 'linear'.

    Zeros (a residual that starts on the constraints) do not make an axis
    linear: a log axis leaves them out, and the decay is what the plot is for.
    NaNs are ignored.

    Examples
    --------
    >>> axis_scale([0.0, 1e-3, 1e-9]), axis_scale([1.0, 2.0]), axis_scale([-1e-9, 1.0])
    ('log', 'linear', 'linear')
    """
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    positive = values[values > 0]
    if values.size == 0 or np.any(values < 0) or positive.size < 2:
        return "linear"
    return "log" if positive.max() > DECADES * positive.min() else "linear"


def unit_of(variable):
    """The unit a model description gives a variable (its own, else its declared type's), or None."""
    if variable is None:
        return None
    unit = getattr(variable, "unit", None) or getattr(getattr(variable, "declaredType", None), "unit", None)
    return unit or None


def time_unit(md):
    """The unit of the FMU's time: its independent variable's unit, or seconds for an FMU lsc built.

    lsc's specs state rates in 1/s (``lambda``), so its FMUs count time in
    seconds; another FMU's time unit is not guessed (None).
    """
    for v in md.modelVariables:
        if v.causality == "independent":
            unit = unit_of(v)
            if unit:
                return unit
    from .cosim._run import built_by_lsc

    return "s" if built_by_lsc(md) else None


def label(name, unit):
    """``name [unit]``, or the name alone when the unit is unknown."""
    return f"{name} [{unit}]" if unit else name


def simulation_figure(result, outputs, md, title):
    """One panel per output against time, each on the axis its values need, labelled with units."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variables = {v.name: v for v in md.modelVariables}
    fig, axes = plt.subplots(len(outputs), 1, sharex=True, figsize=(7, 1.6 * len(outputs) + 1), squeeze=False)
    for ax, output in zip(axes[:, 0], outputs):
        values = np.asarray(result[output], dtype=float)
        ax.plot(result["time"], values)
        ax.set_ylabel(label(output, unit_of(variables.get(output))))
        ax.set_yscale(axis_scale(values))
    axes[-1, 0].set_xlabel(label("time", time_unit(md)))
    fig.suptitle(title)
    fig.tight_layout()
    return fig
