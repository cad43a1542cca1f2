"""The points of a study's grid, and the names of its metric columns."""
import itertools
import math

import numpy as np

from ._runs import NUMERICAL

METRICS = ("success", "message", "error", "residual_final", "residual_peak", "run_time", "steps")
_LOG_SAMPLED = ("lam", "step", "rtol", "atol")
# Grid names whose values must be real numbers (a bool or a text would be read as one silently).
_REAL = ("lam", "step", "rtol", "atol", "offset", "k", "extrapolation", "iterations")


def _check_names(names):
    for name in names:
        if name in METRICS or name == "run":
            raise ValueError(f"`grid` name {name!r} is a column of the result (`run` and {', '.join(METRICS)}); "
                             "it would overwrite the input in the table: rename the input.")


def _check_values(name, values):
    if name not in _REAL:
        return
    for value in values:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise TypeError(f"`grid[{name!r}]` must hold real numbers; found {value!r} ({type(value).__name__}).")


# -- the grid ------------------------------------------------------------------
def _points(grid, seed):
    """The list of points (dicts) and the input names, in the grid's order."""
    if isinstance(grid, dict):
        if not grid:
            raise ValueError("`grid` must name at least one input; found an empty dict.")
        names = list(grid)
        _check_names(names)
        lists = []
        for name in names:
            values = grid[name]
            if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
                raise TypeError(f"`grid[{name!r}]` must be a list of values; found {type(values).__name__}.")
            values = list(values)
            if not values:
                raise ValueError(f"`grid[{name!r}]` must hold at least one value; found an empty list.")
            _check_values(name, values)
            lists.append(values)
        return [dict(zip(names, combo)) for combo in itertools.product(*lists)], names
    if isinstance(grid, tuple) and len(grid) == 2 and isinstance(grid[1], dict):
        size, ranges = grid
        if not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"the sample size of `grid` must be a positive integer; found {size!r}.")
        from scipy.stats import qmc

        names = list(ranges)
        _check_names(names)
        for name in names:
            lo_hi = ranges[name]
            if len(lo_hi) != 2 or not lo_hi[0] < lo_hi[1]:
                raise ValueError(f"`grid` range of {name!r} must be (low, high) with low < high; found {lo_hi!r}.")
        unit = qmc.LatinHypercube(d=len(names), seed=seed).random(int(size))
        points = [{} for _ in range(int(size))]
        for j, name in enumerate(names):
            lo, hi = (float(v) for v in ranges[name])
            if name in _LOG_SAMPLED and lo > 0:  # rates, steps and tolerances vary over decades
                values = np.exp(np.log(lo) + unit[:, j] * (np.log(hi) - np.log(lo)))
            else:
                values = lo + unit[:, j] * (hi - lo)
            for point, value in zip(points, values):
                point[name] = float(value)
        return points, names
    raise TypeError("`grid` must be a dict of value lists (full grid) or (sample size, {name: (low, high)}) "
                    f"(Latin hypercube); found {type(grid).__name__}.")


def _group_key(point):
    return tuple((k, v) for k, v in point.items() if k not in NUMERICAL)


def _tightest(points):
    """Per group of model inputs, the tightest point: smallest step and tolerances, largest lam."""
    out = {}
    for point in points:
        key = _group_key(point)
        best = out.setdefault(key, dict(point))
        for name in ("step", "rtol", "atol"):
            if name in point and point[name] < best[name]:
                best[name] = point[name]
        if "lam" in point and point["lam"] > best["lam"]:
            best["lam"] = point["lam"]
    return out


def _valid(point):
    return all(not (isinstance(v, float) and not math.isfinite(v)) for v in point.values()) and all(
        point[n] > 0 for n in ("lam", "step", "rtol", "atol") if n in point and isinstance(point[n], (int, float)))

