"""The cheapest run that reaches an error target, and the summary plots."""
import math
import os

import numpy as np

from ._grid import METRICS

# -- the recommendation ----------------------------------------------------------
class Recommendation:
    """The cheapest run of a study that reaches an error target.

    Attributes
    ----------
    row : pandas.Series or None
        The recommended run (None if no run reaches the target).
    evidence : pandas.DataFrame
        The runs the choice rests on: the recommended one, the cheaper runs
        that miss the target, and the next more expensive runs that reach it.
    error_target : float
    cost : str
        The column minimized.
    on : str
        The column held to the target.
    rule : str
        The rule of thumb the recommended point suggests: ``lam`` relative to
        the horizon, to the fastest kept eigenvalue and to the step.
    """

    def __init__(self, row, evidence, error_target, cost, rule, on="error"):
        self.row, self.evidence, self.error_target, self.cost, self.rule = row, evidence, error_target, cost, rule
        self.on = on

    def __str__(self):
        import pandas as pd

        with pd.option_context("display.width", 160, "display.max_columns", 20, "display.max_colwidth", 40):
            head = (f"no run reaches {self.on} <= {self.error_target:g}" if self.row is None else
                    f"recommended ({self.on} <= {self.error_target:g} at least {self.cost}): "
                    + ", ".join(f"{k}={getattr(v, 'item', lambda: v)()!r}" for k, v in self.row.items() if k not in METRICS))
            return f"{head}\n{self.rule}\nevidence:\n{self.evidence.to_string()}"


def recommend(df, error_target, *, cost="run_time", on="error", horizon=None, eigenvalues=None, step=None,
              offset=None):
    """The cheapest run that reaches an error target, with the evidence.

    Parameters
    ----------
    df : pandas.DataFrame
        From `sweep`.
    error_target : float
        Largest acceptable value of the `on` column.
    cost : str, optional
        Column to minimize: 'run_time' (default) or 'steps' (deterministic).
        Ties go to the smaller error.
    on : str, optional
        The column held to `error_target`: 'error' (default) or
        'residual_final' (the drift from the constraints, which is what λ
        governs; the state error also carries whatever part of an initial
        offset the completion moves along the solution manifold).
    horizon : float, optional
        Time over which the initial offset must decay (default: the study's
        horizon from ``df.attrs['t_span']`` minus nothing); used for the rule.
    eigenvalues : array_like, optional
        Finite eigenvalues of the DAE (kept by the completion), for the rule.
    step : float, optional
        Communication or integrator step, for the rule (default: the row's
        ``step`` if the grid has one).
    offset : float, optional
        Initial distance from the manifold (default: the row's ``offset``).

    Returns
    -------
    Recommendation

    Examples
    --------
    >>> import pandas as pd
    >>> df = pd.DataFrame({"lam": [1.0, 2.0, 4.0, 8.0], "success": True, "message": "",
    ...                    "error": [1e-1, 1e-3, 1e-6, 1e-7], "residual_final": 0.0,
    ...                    "residual_peak": 0.0, "run_time": 0.1, "steps": [50, 52, 60, 90]})
    >>> float(recommend(df, 1e-5, cost="steps").row["lam"])
    4.0
    """
    import pandas as pd

    if cost not in df.columns:
        raise ValueError(f"`cost` must be a column of `df`; found {cost!r}.")
    if not pd.api.types.is_numeric_dtype(df[cost]) or pd.api.types.is_bool_dtype(df[cost]):
        raise ValueError(f"`cost` must be a numeric column ('run_time', 'steps'); found {cost!r} "
                         f"({df[cost].dtype}).")
    real = isinstance(error_target, (int, float, np.integer, np.floating)) and not isinstance(error_target, bool)
    if not (real and math.isfinite(error_target) and error_target > 0):
        raise ValueError(f"`error_target` must be a positive finite number; found {error_target!r}.")
    if on not in ("error", "residual_final"):
        raise ValueError(f"`on` must be 'error' or 'residual_final'; found {on!r}.")
    ok = df[df["success"] & (df[on] <= error_target)]
    inputs = [c for c in df.columns if c not in METRICS and c in df.columns[: list(df.columns).index("success")]]
    if ok.empty:
        evidence = df[df["success"]].sort_values(on).head(5)
        return Recommendation(None, evidence, error_target, cost, "no rule: the study never reaches the target; "
                              "widen the grid (larger lam, smaller step or tolerances).")
    ranked = ok.sort_values([cost, on], kind="stable")
    best = ranked.iloc[0]
    cheaper_missing = df[(df[cost] <= best[cost]) & ~(df["success"] & (df[on] <= error_target))]
    chosen = [ranked.index[0], *cheaper_missing.sort_values(cost).index[:4], *ranked.index[1:4]]
    evidence = df.loc[list(dict.fromkeys(chosen))]
    t_span = df.attrs.get("t_span")
    if horizon is None and t_span:
        horizon = t_span[1] - t_span[0]
    rule = _rule(best, horizon, error_target, eigenvalues, step, offset)
    return Recommendation(best[inputs + list(METRICS)], evidence, error_target, cost, rule, on)


def _rule(best, horizon, error_target, eigenvalues, step, offset):
    if "lam" not in best.index:
        return "no rule: the study does not vary lam."
    lam = float(best["lam"])
    parts = [f"lam = {lam:.4g}"]
    offset = offset if offset is not None else best.get("offset")
    if horizon:
        parts.append(f"lam * horizon = {lam * horizon:.3g}")
        if offset is not None and offset > 0:
            parts.append(f"ln(offset / error_target) = {math.log(float(offset) / error_target):.3g} "
                         f"(an offset decaying like exp(-lam t) reaches the target at lam * horizon = that)")
    if eigenvalues is not None and np.size(eigenvalues):
        fastest = float(np.max(np.abs(np.real(eigenvalues))))
        if fastest > 0:
            parts.append(f"lam / |Re mu|max = {lam / fastest:.3g}")
    step = step if step is not None else best.get("step")
    if step is not None:
        parts.append(f"lam * step = {lam * float(step):.3g}")
    return "rule of thumb: " + ", ".join(parts)


# -- plots -------------------------------------------------------------------------
def plot_study(df, path, *, cost="run_time", max_curves=12):
    """Summary plots of a study as a PNG: error and cost against lam, residual decay curves.

    Parameters
    ----------
    df : pandas.DataFrame
        From `sweep` (with a ``lam`` column).
    path : path
        PNG file to write.
    cost : str, optional
        Cost column ('run_time' or 'steps').
    max_curves : int, optional
        Residual curves drawn at most (from ``df.attrs['curves']``).

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    import pathlib

    import matplotlib.pyplot as plt

    if "lam" not in df.columns:
        raise ValueError("`df` must have a `lam` column to plot against.")
    if os.path.isdir(path):
        raise ValueError(f"`path` {os.fspath(path)!r} is a folder; give a .png file name.")
    if not os.path.isdir(os.path.dirname(os.path.abspath(path))):
        raise ValueError(f"`path` {os.fspath(path)!r}: the folder {os.path.dirname(os.path.abspath(path))!r} "
                         "does not exist.")
    fig = study_figure(df, cost=cost, max_curves=max_curves)
    path = pathlib.Path(path)
    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)
    return path


def study_figure(df, *, cost="run_time", max_curves=12):
    """The figure of `plot_study`: error and cost against lam, residual curves against time.

    The axes of lam and of the values are logarithmic where they span decades
    (`fmu_build._cli_plots.axis_scale`); time and lam carry the FMU's time
    unit when the study knows it (``df.attrs['time_unit']``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .._cli_plots import axis_scale, label

    unit = df.attrs.get("time_unit")
    inputs = [c for c in df.columns[: list(df.columns).index("success")] if c != "lam"]
    ok = df[df["success"]]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    def described(row):  # the group's inputs other than lam, as in the legend
        return ", ".join(f"{n}={v:g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else f"{n}={v}"
                         for n, v in zip(inputs, row))

    groups = ok.groupby(inputs, sort=True) if inputs else [((), ok)]
    for key, group in groups:
        group = group.sort_values("lam")
        name = described(key if isinstance(key, tuple) else (key,)) or None
        axes[0].plot(group["lam"], group["error"], "o-", label=name)
        axes[1].plot(group["lam"], group[cost], "o-", label=name)
    lam_label = label("lam", f"1/{unit}" if unit else None)
    lam_scale = axis_scale(ok["lam"])  # log where lam spans decades, as the value axes
    axes[0].set(xlabel=lam_label, ylabel="error", title="error against lam", xscale=lam_scale,
                yscale=axis_scale(ok["error"]))
    axes[1].set(xlabel=lam_label, ylabel=label(cost, "s" if cost == "run_time" else None),
                title=f"cost ({cost}) against lam", xscale=lam_scale, yscale=axis_scale(ok[cost]))
    if axes[1].get_yscale() == "linear":
        axes[1].set_ylim(bottom=0.0)  # a flat cost looks flat, not like noise magnified
    if inputs and len(ok.groupby(inputs)) <= 8:
        axes[0].legend(fontsize=7)
    curves = df.attrs.get("curves", {})
    chosen = sorted((r for r in curves if r in ok.index), key=lambda r: ok.loc[r, "lam"])
    if len(chosen) > max_curves:
        chosen = [chosen[i] for i in np.linspace(0, len(chosen) - 1, max_curves).astype(int)]
    drawn = []
    for run in chosen:
        t, r = curves[run]
        others = described(ok.loc[run, inputs]) if inputs else ""
        axes[2].plot(t, r, label=f"lam={ok.loc[run, 'lam']:g}" + (f", {others}" if others else ""))
        drawn.append(np.asarray(r, dtype=float))
    axes[2].set(xlabel=label("t", unit), ylabel="constraint residual", title="residual decay",
                yscale=axis_scale(np.concatenate(drawn)) if drawn else "linear")
    if chosen:
        axes[2].legend(fontsize=7)
    fig.tight_layout()
    return fig
