"""Checks the command line makes before it runs anything: times, files, outputs, input CSVs.

Each check raises ValueError with one sentence naming the option or the file,
what was expected and what was found; the command prints it and exits 2.
"""
import csv
import math
import os
import re
import zipfile

# A run of more communication steps than this is refused: it would not end in useful time.
MAX_STEPS = 10_000_000


# A plain decimal number: Python's float() would also read '1_0' as 10, and int() '0x10' with base 0.
_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[+-]?(inf|nan)", re.IGNORECASE)
# FMI 2.0 Integer variables are C ints.
_INT_RANGE = (-2**31, 2**31 - 1)


def decimal(text):
    """`text` as a float if it is a plain decimal number (``1``, ``-2.5``, ``1e-3``, ``inf``), else None."""
    text = text.strip()
    return float(text) if _DECIMAL.fullmatch(text) else None


def assignments(items, option, form):
    """``{name: text}`` from repeated ``NAME=VALUE`` options; a name given twice is refused."""
    values = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name or not value.strip():
            raise ValueError(f"`{option}` expects {form}; found {item!r}.")
        if name in values:
            raise ValueError(f"`{option}` gives `{name}` twice ({values[name]!r} and {value.strip()!r}); give it once.")
        values[name] = value.strip()
    return values


def typed_start_values(items, variables, option="--set"):
    """``{name: value}`` from ``NAME=VALUE`` texts, each read by its FMU variable's type.

    Real: a decimal number. Integer: a whole decimal number in the C int range
    (1.7 is not 1). Boolean: true/false/1/0 (0.5 is neither). String: the text.
    A name that is not a variable is left to fmpy, which refuses it.
    """
    types = {v.name: v.type for v in variables}
    values = {}
    for name, text in assignments(items, option, "NAME=VALUE").items():
        kind = types.get(name, "Real")
        if kind == "String":
            values[name] = text
            continue
        if kind == "Boolean":
            flag = {"true": True, "1": True, "false": False, "0": False}.get(text.lower())
            if flag is None:
                raise ValueError(f"`{option}` {name}={text!r}: `{name}` is a Boolean; expected true, false, 1 or 0.")
            values[name] = flag
            continue
        value = decimal(text)
        if value is None:  # a Real may be non-finite: the FMU refuses it with its own reason
            raise ValueError(f"`{option}` {name}={text!r}: expected a plain decimal number.")
        if kind in ("Integer", "Enumeration"):
            if not math.isfinite(value) or value != int(value) or not _INT_RANGE[0] <= value <= _INT_RANGE[1]:
                raise ValueError(f"`{option}` {name}={text!r}: `{name}` is an {kind}; expected a whole number in "
                                 f"[{_INT_RANGE[0]}, {_INT_RANGE[1]}].")
            value = int(value)
        values[name] = value
    return values


def check_time(value, option):
    """`value` (or None) as a finite float."""
    if value is not None and not math.isfinite(value):
        raise ValueError(f"`{option}` must be a finite number; found {value!r}.")
    return value


def check_step(value, option):
    """`value` (or None) as a positive finite float."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ValueError(f"`{option}` must be a positive finite number; found {value!r}.")
    return value


def check_span(start, stop, step, stop_option, step_option):
    """Refuse a horizon that is empty or would take more than MAX_STEPS steps."""
    if not stop > start:
        raise ValueError(f"`{stop_option}` ({stop!r}) must be after the start time ({start!r}).")
    if step is not None and (stop - start) / step > MAX_STEPS:
        raise ValueError(f"`{step_option}` {step!r} over [{start!r}, {stop!r}] makes {(stop - start) / step:.3g} "
                         f"communication steps (at most {MAX_STEPS:.0e}); give a larger step.")
    # fmpy ends a run at a time within 1e-9 relative of the stop time (math.isclose): a step below
    # that resolution would end the run after one step.
    scale = max(abs(start), abs(stop))
    if step is not None and step <= 1e-8 * scale:
        raise ValueError(f"`{step_option}` {step!r} is too small for times near {scale:g}: fmpy resolves times to "
                         f"1e-9 relative ({1e-9 * scale:.3g}); give a step above {1e-8 * scale:.3g} or shift "
                         "the time origin.")


def _same_file(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def _header(path):
    """The cells of a file's first line (quotes stripped), or None if it is not a text line."""
    try:
        with open(path, encoding="utf-8") as fh:
            line = fh.readline(100_000)
    except (OSError, UnicodeDecodeError):
        return None
    return [cell.strip().strip('"') for cell in line.rstrip("\r\n").split(",")]


def is_result(path, columns=None):
    """True if `path` holds a result this command writes: a CSV whose header is ``time`` then `columns`.

    Without `columns` (a co-simulation whose recorded variables are decided by
    the run), the header must be ``time`` followed by ``component.variable``
    names.
    """
    header = _header(path)
    if not header or header[0] != "time":
        return False
    if columns is not None:
        return header == ["time", *columns]
    return len(header) > 1 and all("." in cell for cell in header[1:])


def check_parent(output, option):
    """Refuse an output below an existing file (its folder cannot be made)."""
    parent = os.path.dirname(os.path.abspath(output))
    while parent and not os.path.exists(parent):
        parent = os.path.dirname(parent)
    if parent and not os.path.isdir(parent):
        raise ValueError(f"`{option}` {os.fspath(output)!r} is below {parent!r}, which is a file, not a folder.")


def check_output(output, inputs, option, force, columns=None):
    """Refuse an output that is one of `inputs` (however spelled) or an existing file that is not a result."""
    check_parent(output, option)
    for given in inputs:
        if given is not None and os.path.exists(given) and os.path.exists(output) and _same_file(output, given):
            raise ValueError(f"`{option}` {os.fspath(output)!r} is the input {os.fspath(given)!r}: writing the "
                             "result there would destroy it; choose another file.")
    if os.path.isdir(output):
        raise ValueError(f"`{option}` {os.fspath(output)!r} is a folder; give a file name.")
    if os.path.exists(output) and not force:
        png = os.fspath(output).lower().endswith(".png")
        if not (_is_png(output) if png else is_result(output, columns)):
            what = "a PNG" if png else "a result of this command (a CSV whose header row starts with 'time')"
            raise ValueError(f"`{option}` {os.fspath(output)!r} exists and is not a result: it is not {what}; "
                             "pass --force to replace it.")


def _is_png(path):
    with open(path, "rb") as fh:
        return fh.read(8) == b"\x89PNG\r\n\x1a\n"


def _looks_like_spec(path):
    import tomllib

    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except (OSError, ValueError):
        return False
    return "equations" in data or "model" in data


def check_fmu_file(path):
    """Refuse a path that is not an FMU archive, saying how to make one."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ValueError(f"`fmu` {path!r} does not exist.")
    if path.lower().endswith(".toml") and _looks_like_spec(path):
        raise ValueError(f"`fmu` {path!r} is a model spec, not an FMU: build it first with "
                         f"`lsc-fmu build {path} -o out`, then simulate out/<model name>.fmu.")
    if not zipfile.is_zipfile(path) or "modelDescription.xml" not in zipfile.ZipFile(path).namelist():
        raise ValueError(f"`fmu` {path!r} is not an FMU (a zip archive holding modelDescription.xml); "
                         "make one from a TOML spec with `lsc-fmu build SPEC.toml -o out`.")


def check_system_file(path):
    """Refuse a path that cannot be a co-simulation system, saying what is expected."""
    path = os.fspath(path)
    lower = path.lower()
    if not os.path.exists(path):
        raise ValueError(f"`system` {path!r} does not exist.")
    if lower.endswith(".toml") and _looks_like_spec(path):
        raise ValueError(f"`system` {path!r} is a model spec of one component, not a system: build its FMU with "
                         f"`lsc-fmu build {path} -o out`, then connect FMUs in an SSP file (.ssp or .ssd; "
                         "see docs/cosimulation.md, whose examples/plants/scenarios.py writes one).")
    if lower.endswith(".fmu"):
        raise ValueError(f"`system` {path!r} is an FMU, not a system: run it alone with `lsc-fmu simulate {path}`, "
                         "or connect it to others in an SSP file (.ssp or .ssd; see docs/cosimulation.md).")
    if lower.endswith(".ssp") and (not zipfile.is_zipfile(path)
                                   or "SystemStructure.ssd" not in zipfile.ZipFile(path).namelist()):
        raise ValueError(f"`system` {path!r} is not an SSP archive (a zip file holding SystemStructure.ssd).")


def _cell(text, row, column, path):
    if not text.strip():
        raise ValueError(f"`--input` {path}: row {row}, column `{column}` is empty.")
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"`--input` {path}: row {row}, column `{column}` holds {text.strip()!r}, not a number.") from None
    if not math.isfinite(value):
        raise ValueError(f"`--input` {path}: row {row}, column `{column}` holds {value!r}; values must be finite.")
    return value


def check_input_csv(path, inputs, set_names, span=None):
    """Read and check an input CSV; return its rows as a numpy structured array.

    `inputs` maps each FMU input to its start value (None if it has none);
    `set_names` are the names given a value on the command line. Rows are
    numbered as lines of the file (the header is row 1).
    """
    import numpy as np

    path = os.fspath(path)
    if os.path.isdir(path):
        raise ValueError(f"`--input` {path!r} is a folder; expected a CSV file.")
    if not os.path.isfile(path):
        raise ValueError(f"`--input` {path!r} does not exist.")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:  # a spreadsheet's byte-order mark is not a name
            rows = list(csv.reader(fh))
    except UnicodeDecodeError as exc:
        raise ValueError(f"`--input` {path} is not a text CSV file ({exc.reason} at byte {exc.start}).") from None
    if not rows or [c.strip() for c in rows[0]][:1] != ["time"]:
        raise ValueError(f"`--input` {path}: the first column must be 'time', found {rows[0] if rows else 'no header'}.")
    header = [c.strip() for c in rows[0]]
    for i, name in enumerate(header):
        if name in header[:i]:
            raise ValueError(f"`--input` {path}: column `{name}` appears twice in the header; give each once.")
    for name in header[1:]:
        if name not in inputs:
            raise ValueError(f"`--input` {path}: column `{name}` is not an input of the FMU; its inputs are "
                             f"{sorted(inputs)}.")
    for name in header[1:]:
        if name in set_names:
            raise ValueError(f"`--input` {path}: input `{name}` has a column there and a value by --set {name}=...; "
                             "give it one way only.")
    for name, start in inputs.items():
        if name not in header and start is None and name not in set_names:
            raise ValueError(f"input `{name}` has no column in {path} and no start value; add a column or "
                             f"--set {name}=VALUE.")
    data = []
    for number, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise ValueError(f"`--input` {path}: row {number}: the header has {len(header)} cells; "
                             f"found {len(row)}.")
        values = [_cell(text, number, name, path) for text, name in zip(row, header)]
        if data and not values[0] > data[-1][0]:
            raise ValueError(f"`--input` {path}: row {number}: `time` {values[0]!r} does not increase "
                             f"(the row before has {data[-1][0]!r}); times must strictly increase.")
        data.append(tuple(values))
    if not data:
        raise ValueError(f"`--input` {path} has no data rows.")
    if span is not None and (data[0][0] > span[0] or data[-1][0] < span[1]):
        # fmpy would hold the first or last value outside the file's times: a signal nobody gave
        raise ValueError(f"`--input` {path}: `time` covers [{data[0][0]!r}, {data[-1][0]!r}], which does not "
                         f"cover the run's horizon [{span[0]!r}, {span[1]!r}].")
    return np.array(data, dtype=[(name, float) for name in header])
