"""The points of a study's grid, and the names of its metric columns."""
import itertools
import math

import numpy as np

from ._runs import NUMERICAL

METRICS = ("success", "message", "error", "residual_final", "residual_peak", "run_time", "steps")
_LOG_SAMPLED = ("lam", "step", "rtol", "atol")
# Grid names whose values must be real numbers (a bool or a text would be read as one silently).
_REAL = ("lam", "step", "rtol", "atol", "offset", "k", "extrapolation", "iterations")


# Names a Latin hypercube cannot sample: categories and counts, not numbers.
_CATEGORICAL = ("method", "completion", "extrapolation", "iterations", "algorithm", "exchange")
# Names of one variable: a grid giving two of them would let one silently win.
_ALIASES = (("lam", "lambda"), ("method", "solver"))
# Runs a study materializes at most (a grid's points are a list of dicts, its identity a JSON file).
MAX_POINTS = 10 ** 6


def _check_names(names):
    for name in names:
        if not isinstance(name, str):
            raise TypeError(f"`grid` names must be texts; found {name!r} ({type(name).__name__}).")
        if name in METRICS or name == "run":
            raise ValueError(f"`grid` name {name!r} is a column of the result (`run` and {', '.join(METRICS)}); "
                             "it would overwrite the input in the table: rename the input.")
    pairs = [pair for pair in _ALIASES if set(pair) <= set(names)]
    if "lam" in names and any(name.endswith(".lambda") for name in names):
        pairs.append(("lam", *[name for name in names if name.endswith(".lambda")]))
    if pairs:
        raise ValueError(f"`grid` names {list(pairs[0])} set the same variable (`lam` is `lambda`, `method` is "
                         "`solver`, and `lam` sets every component's `lambda`): one would silently win; give one.")


def _check_values(name, values):
    if name not in _REAL:
        return
    for value in values:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise TypeError(f"`grid[{name!r}]` must hold real numbers; found {value!r} ({type(value).__name__}).")


def _is_real(value):
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def value_lists(grid):
    """``{name: [values]}`` of a full grid, checked, each iterable read once (a generator too)."""
    if not grid:
        raise ValueError("`grid` must name at least one input; found an empty dict.")
    _check_names(list(grid))
    lists = {}
    for name, values in grid.items():
        if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__") or (
                isinstance(values, np.ndarray) and values.ndim == 0):
            raise TypeError(f"`grid[{name!r}]` must be a list of values; found {type(values).__name__}.")
        values = list(values)
        if not values:
            raise ValueError(f"`grid[{name!r}]` must hold at least one value; found an empty list.")
        _check_values(name, values)
        lists[name] = values
    return lists


def _check_size(count):
    if count > MAX_POINTS:
        raise ValueError(f"`grid` has {count} points, more than a study runs ({MAX_POINTS}): sample the space "
                         "with a Latin hypercube, or split the study.")


def _check_ranges(size, ranges):
    if isinstance(size, (bool, np.bool_)) or not isinstance(size, (int, np.integer)) or size < 1:
        raise ValueError(f"the sample size of `grid` must be a positive integer; found {size!r}.")
    _check_size(int(size))
    if not isinstance(ranges, dict) or not ranges:
        raise ValueError("a Latin hypercube `grid` must name at least one input range; found none.")
    _check_names(list(ranges))
    for name, lo_hi in ranges.items():
        if name in _CATEGORICAL:
            raise ValueError(f"`grid` range of {name!r}: `{name}` takes categories, which a Latin hypercube cannot "
                             "sample; give it as a list in a full grid.")
        if isinstance(lo_hi, (str, bytes)) or np.ndim(lo_hi) != 1 or len(lo_hi) != 2 or \
                not all(_is_real(v) for v in lo_hi):
            raise TypeError(f"`grid` range of {name!r} must be (low, high), two real numbers; found {lo_hi!r}.")
        lo, hi = (float(v) for v in lo_hi)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"`grid` range of {name!r} must be (low, high), finite with low < high; found {lo_hi!r}.")
        if name in _LOG_SAMPLED and not lo > 0:
            raise ValueError(f"`grid` range of {name!r} must be positive (it is sampled log-uniformly, and "
                             f"`{name}` <= 0 is no run); found {lo_hi!r}.")


# -- the grid ------------------------------------------------------------------
def _points(grid, seed):
    """The list of points (dicts) and the input names, in the grid's order."""
    if isinstance(grid, dict):
        lists = value_lists(grid)
        _check_size(math.prod(len(values) for values in lists.values()))
        names = list(lists)
        return [dict(zip(names, combo)) for combo in itertools.product(*lists.values())], names
    if isinstance(grid, tuple) and len(grid) == 2 and isinstance(grid[1], dict):
        size, ranges = grid
        _check_ranges(size, ranges)
        from scipy.stats import qmc

        names = list(ranges)
        unit = qmc.LatinHypercube(d=len(names), seed=seed).random(int(size))
        points = [{} for _ in range(int(size))]
        for j, name in enumerate(names):
            lo, hi = (float(v) for v in ranges[name])
            if name in _LOG_SAMPLED:  # rates, steps and tolerances vary over decades
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
    """Per group of model inputs, the grid's tightest point: smallest step and tolerances, largest lam.

    Taken over the whole grid, not over each group: in a full grid every group
    holds the same numerical values, but in a Latin hypercube with model inputs
    every point is a group of its own, and its own reference.
    """
    tightest = {}
    for point in points:
        for name, better in (("step", min), ("rtol", min), ("atol", min), ("lam", max)):
            if name in point:
                tightest[name] = better(tightest.get(name, point[name]), point[name])
    out = {}
    for point in points:
        out.setdefault(_group_key(point), {**point, **{k: v for k, v in tightest.items() if k in point}})
    return out


def _valid(point):
    return all(not (isinstance(v, float) and not math.isfinite(v)) for v in point.values()) and all(
        point[n] > 0 for n in ("lam", "step", "rtol", "atol") if n in point and isinstance(point[n], (int, float)))

