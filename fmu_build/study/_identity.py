"""A study's identity: what makes two studies the same, stored with the output and compared when resuming."""
import os

import numpy as np


def _identity(target, payload, grid, seed, names, reference, settings, metrics):
    """What makes two studies the same: stored with the output, compared when resuming.

    The grid's values are part of it: 'tightest' takes its reference from the
    grid, so rows of a smaller grid were measured against another reference.
    A callable reference is identified by its values at three times of the
    horizon, not only by its name (every lambda is called ``<lambda>``).
    """
    import hashlib

    import lsc

    path = payload if isinstance(payload, str) and os.path.isfile(payload) else None
    if isinstance(target, lsc.gallery.Problem):
        what = {"gallery": target.name}
    elif isinstance(target, lsc.LinearDAE):
        what = {"LinearDAE": [float(v) for v in np.ravel(payload["x0"])]}
    elif isinstance(target, dict):
        what, path = {"spec": repr(sorted(target.items()))}, None  # two builds of a spec differ in their bytes
    else:
        what = {"file": os.path.basename(os.fspath(target))}
        if what["file"].lower().endswith(".toml"):
            path = os.fspath(target)  # the spec, not its build (a GUID and a time stamp of its own)
    if path:  # the FMU or the spec by its content
        with open(path, "rb") as fh:
            what["sha256"] = hashlib.sha256(fh.read()).hexdigest()
    t_span = settings["t_span"]
    if isinstance(grid, dict):
        values = {name: [_plain(v) for v in grid[name]] for name in names}
    else:
        values = {"sample": int(grid[0]), "seed": _plain(seed),
                  "ranges": {name: [_plain(v) for v in grid[1][name]] for name in names}}
    return {"target": what, "grid names": list(names), "grid": values, "reference": _reference_identity(reference, t_span),
            "t_span": [float(t) for t in t_span] if t_span else None,
            "error_from": None if settings["error_from"] is None else float(settings["error_from"]),
            "metrics": sorted(metrics)}


def _plain(value):
    """A grid value as JSON keeps it (numpy scalars as Python numbers)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    return value if isinstance(value, str) or value is None else repr(value)


def _reference_identity(reference, t_span):
    if isinstance(reference, str):
        return reference
    name = "callable " + getattr(reference, "__qualname__", type(reference).__name__)
    if not t_span:
        return name
    times = [float(t_span[0]), 0.5 * (float(t_span[0]) + float(t_span[1])), float(t_span[1])]
    try:
        values = np.asarray(reference(np.array(times)), dtype=float)
    except Exception as exc:  # a reference that cannot be evaluated fails every row's error, and says why there
        return {"callable": name, "evaluated": f"{type(exc).__name__}: {exc}"}
    return {"callable": name, "times": times, "values": [float(f"{v:.12g}") for v in values.ravel()]}
