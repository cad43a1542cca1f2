"""The output file of a study: reading finished rows back, writing rows."""
import math
import os

from ._grid import METRICS

# -- the output file -----------------------------------------------------------
def _stream_path(output):
    output = os.fspath(output)
    return output if output.lower().endswith(".csv") else output + ".partial.csv"


def _read_finished(output, names, points):
    """Rows already in the output file that match the study's points, as {run: row dict}."""
    import pandas as pd

    frames = []
    stream = _stream_path(output)
    if os.fspath(output).lower().endswith(".parquet") and os.path.exists(output):
        frames.append(pd.read_parquet(output).reset_index())
    if os.path.exists(stream) and os.path.getsize(stream) > 0:
        # an interrupted write leaves at most a broken last line: skip what does not parse
        frames.append(pd.read_csv(stream, on_bad_lines="skip", engine="python"))
    if not frames:
        return {}
    old = pd.concat(frames, ignore_index=True)
    missing = [c for c in ["run", *names, *METRICS] if c not in old.columns]
    if missing:
        raise ValueError(f"`output` {os.fspath(output)!r} holds another study: it lacks the columns {missing}.")
    old = old.dropna(subset=["run", "success", "run_time"]).drop_duplicates("run", keep="last")
    finished = {}
    for row in old.to_dict("records"):
        run = int(row["run"])
        if not 0 <= run < len(points):
            raise ValueError(f"`output` {os.fspath(output)!r} holds run {run}, outside this study of {len(points)} runs.")
        for name in names:
            a, b = row[name], points[run][name]
            same = (a == b) or (isinstance(b, (int, float)) and isinstance(a, (int, float))
                                and (math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0) or (math.isnan(a) and math.isnan(b))))
            if not same and str(a) != str(b):
                raise ValueError(f"`output` {os.fspath(output)!r} holds another study: run {run} has {name}={a!r}, "
                                 f"this study {b!r}.")
        row["success"] = row["success"] in (True, "True", 1)
        row["message"] = "" if row["message"] is None or (isinstance(row["message"], float)) else row["message"]
        finished[run] = row
    return finished


def _rewrite(path, rows, columns):
    """Write the rows kept from an interrupted study atomically (temp file, then os.replace)."""
    import pandas as pd

    tmp = f"{path}.tmp{os.getpid()}"
    pd.DataFrame(rows, columns=columns).to_csv(tmp, index=False)
    os.replace(tmp, path)

