"""The output file of a study: reading finished rows back, writing rows."""
import math
import os

import numpy as np

from ._grid import METRICS


def check_output(output):
    """Refuse an output the study could not write as asked, before anything runs."""
    path = os.fspath(output)
    if os.path.isdir(path) or not path.lower().endswith((".csv", ".parquet")):
        raise ValueError(f"`output` must be a .csv or .parquet file; found {path!r}.")
    if path.lower().endswith(".parquet"):
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise ImportError(f"`output` {path!r}: writing Parquet needs pyarrow (pip install pyarrow); "
                              "or write a .csv file.") from None


def identity_path(output):
    """The file beside `output` that records the study's identity."""
    return os.fspath(output) + ".study.json"


def check_identity(output, identity):
    """Refuse to resume a study in files written by another one; record the identity of a new one.

    The identity (target, grid names, reference, settings) is stored as JSON
    in ``output + '.study.json'`` before the first row is written.
    """
    import json

    record = identity_path(output)
    data = [p for p in (os.fspath(output), _stream_path(output)) if os.path.exists(p) and os.path.getsize(p) > 0]
    if data and not os.path.exists(record):
        raise ValueError(f"`output` {data[0]!r} exists, but there is no record of the study that wrote it "
                         f"({record!r}): choose another output, or remove it.")
    if data:
        try:
            with open(record, encoding="utf-8") as fh:
                stored = json.load(fh)
            if not isinstance(stored, dict):
                raise ValueError(f"a JSON {type(stored).__name__}, not the object a study writes")
        except (OSError, ValueError) as exc:
            raise ValueError(f"the study record {record!r} cannot be read ({exc}).") from None
        wanted = json.loads(json.dumps(identity))  # tuples as lists, as stored
        different = [k for k in sorted(set(stored) | set(wanted)) if stored.get(k) != wanted.get(k)]
        if different:
            details = "; ".join(f"{k}: {stored.get(k)!r} there, {wanted.get(k)!r} here" for k in different)
            hint = (" Rows measured against another grid's reference ('tightest' takes it from the grid) would be "
                    "mixed with new ones: write this study to another output." if "grid" in different
                    or "reference" in different else "")
            raise ValueError(f"`output` {os.fspath(output)!r} holds another study: {details}.{hint}")
        return
    tmp = f"{record}.tmp{os.getpid()}"
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(identity, fh, indent=1)
    os.replace(tmp, record)


def _stream_path(output):
    output = os.fspath(output)
    return output if output.lower().endswith(".csv") else output + ".partial.csv"


def one_line(message):
    """A message as one line of the output file (an FMU's log may hold line breaks)."""
    return " ".join(str(message).split()) if isinstance(message, str) and ("\n" in message or "\r" in message) \
        else message


def _complete_lines(path):
    """The text of a streamed CSV without a last line that a crash cut short (every row ends with a line break)."""
    with open(path, "rb") as fh:
        data = fh.read()
    if not data.endswith(b"\n"):
        data = data[:data.rfind(b"\n") + 1]
    return data.decode("utf-8")


def _same(text, value):
    """Whether a cell read back as text holds the grid's value (written by pandas as ``str(value)``)."""
    if text == str(value):
        return True
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return False
    try:
        number = float(text)
    except ValueError:
        return False
    return math.isclose(number, value, rel_tol=1e-12, abs_tol=0.0) or (math.isnan(number) and math.isnan(value))


def _read_finished(output, names, points):
    """Rows already in the output file that match the study's points, as {run: row dict}.

    Every cell is read as text and compared with the point's value as the
    study wrote it (a String grid value "1.50" or "NA" is no number and no
    missing value); a finished row takes its grid values from the point.
    """
    import io

    import pandas as pd

    frames = []
    stream = _stream_path(output)
    if os.fspath(output).lower().endswith(".parquet") and os.path.exists(output):
        frames.append(pd.read_parquet(output).reset_index().astype(str))
    if os.path.exists(stream) and os.path.getsize(stream) > 0:
        # an interrupted write leaves at most a broken last line: it is dropped, and what does not parse skipped
        try:
            frames.append(pd.read_csv(io.StringIO(_complete_lines(stream)), on_bad_lines="skip", engine="python",
                                      dtype=str, keep_default_na=False))
        except (UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as exc:
            raise ValueError(f"`output` {stream!r} is not a readable CSV file of a study ({exc}).") from None
    if not frames:
        return {}
    old = pd.concat(frames, ignore_index=True)
    missing = [c for c in ["run", *names, *METRICS] if c not in old.columns]
    if missing:
        raise ValueError(f"`output` {os.fspath(output)!r} holds another study: it lacks the columns {missing}.")
    numbers = [c for c in old.columns if c not in ("run", "success", "message", *names)]
    for column in numbers:  # the metrics (a NaN error, a crashed run's NaN run time, extra metric columns)
        old[column] = pd.to_numeric(old[column].replace("", "nan"), errors="coerce")
    old["run"] = pd.to_numeric(old["run"], errors="coerce")
    old = old[old["success"] != ""].dropna(subset=["run", "run_time", "steps"]).drop_duplicates("run", keep="last")
    finished = {}
    for row in old.to_dict("records"):
        run = int(row["run"])
        if not 0 <= run < len(points):
            raise ValueError(f"`output` {os.fspath(output)!r} holds run {run}, outside this study of {len(points)} runs.")
        for name in names:
            if not _same(row[name], points[run][name]):
                raise ValueError(f"`output` {os.fspath(output)!r} holds another study: run {run} has {name}="
                                 f"{row[name]!r}, this study {points[run][name]!r}.")
            row[name] = points[run][name]
        flag = {"True": True, "False": False}.get(row["success"])
        if flag is None:
            raise ValueError(f"`output` {stream!r}: run {run} has `success` {row['success']!r}, neither True nor "
                             "False; the file was edited or damaged: repair it or choose another output.")
        row["run"], row["success"], row["steps"] = run, flag, int(row["steps"])
        finished[run] = row
    return finished


def _rewrite(path, rows, columns):
    """Write the rows kept from an interrupted study atomically (temp file, then os.replace)."""
    import pandas as pd

    tmp = f"{path}.tmp{os.getpid()}"
    pd.DataFrame(rows, columns=columns).to_csv(tmp, index=False)
    os.replace(tmp, path)

