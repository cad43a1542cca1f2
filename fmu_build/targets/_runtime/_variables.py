"""The FMU's variables: their enumerations, names and registration with pythonfmu."""

from ._lsc import COMPLETIONS

METHODS = tuple(COMPLETIONS)  # the `method` values: positions in lsc's completions (fmu_build.spec.METHODS)
SOLVERS = ("RK45", "DOP853", "Radau", "BDF", "exact", "Magnus4")
EXACT, MAGNUS = SOLVERS.index("exact"), SOLVERS.index("Magnus4")


def start_name(state):
    """Name of a state's start-value parameter, legal in FMI structured naming.

    ``y`` -> ``y_0``; an array element ``x[3]`` -> ``x_0[3]``.
    """
    if state.endswith("]") and "[" in state:
        base, index = state.split("[", 1)
        return f"{base}_0[{index}"
    return state + "_0"


def register_variables(rt, slave):
    """Register the FMU's variables with the pythonfmu `slave`, reading and writing the runtime `rt`.

    The variables are the rows of the build's interface table
    (``MODEL["variables"]``, `fmu_build._interface.Interface.registration`),
    in its order, which gives their value references; each row's role says
    what its getter reads and its setter writes. The values of the settings,
    parameters and start values begin at the rows' start values. Returns
    ``({vr: input name}, {vr: state index})``.
    """
    from pythonfmu import Boolean, Fmi2Causality, Fmi2Variability, Integer, Real

    types = {"Real": Real, "Integer": Integer, "Boolean": Boolean}
    outputs = getattr(rt.model, "OUTPUTS", [])
    position, input_of_vr, state_of_vr = {}, {}, {}
    M = rt.model.MODEL
    for row in M["variables"] if "variables" in M else sparse_rows(M):
        name, role = row["name"], row["role"]
        i = position[role] = position.get(role, -1) + 1  # the row's place among those of its role
        getter, setter = _access(rt, name, role, i, outputs)
        if role in ("lambda", "option", "parameter", "start"):
            rt.values[name] = row["start"]
        var = types[row["type"]](name, causality=getattr(Fmi2Causality, row["causality"]),
                                 variability=getattr(Fmi2Variability, row["variability"]), start=row["start"],
                                 description=row["description"], getter=getter, setter=setter)
        slave.register_variable(var)
        if var.value_reference != row["vr"]:  # pythonfmu numbers them in registration order: the table's
            raise RuntimeError(f"{name}: pythonfmu gave value reference {var.value_reference}; the model "
                               f"description declares {row['vr']}")
        if role == "input":
            input_of_vr[var.value_reference] = name
        elif role == "state":
            state_of_vr[var.value_reference] = i
    return input_of_vr, state_of_vr


def _access(rt, name, role, i, outputs):
    """``(getter, setter)`` of a variable by its role (setter None: read only)."""
    if role in ("lambda", "option", "parameter", "start"):
        return (lambda: rt.values[name]), (lambda v: rt._set(name, v))
    if role == "input":
        return (lambda: rt.inputs[name].value), (lambda v: rt._set_input(name, v))
    if role == "state":
        return (lambda: float(rt.x[i])), None
    if role == "output":
        function = outputs[i]
        return (lambda: rt._output(function)), None
    if role == "residual":
        return rt._residual_norm, None
    raise ValueError(f"{name}: a pythonfmu FMU has no variable of role {role!r}")


def sparse_rows(M):
    """The registration rows of a sparse model's FMU (`fmu_build.targets.sparse_pythonfmu`), made when the
    FMU loads: its n states come from the model's data file, too many to write into the model module.

    The settings' rows come from the build (``MODEL["settings"]``,
    `fmu_build._interface.sparse_pythonfmu_settings`); then, as `fmu_build._interface.pythonfmu_interface`
    orders them for a model without parameters or custom outputs: the start values, the inputs, the
    states, constraint_residual.
    """
    rows = [dict(row) for row in M["settings"]]

    def add(name, kind, causality, variability, role, start=None, description=""):
        rows.append({"name": name, "type": kind, "vr": len(rows), "role": role, "causality": causality,
                     "variability": variability, "start": start, "description": description})

    for s in M["states"]:
        add(start_name(s["name"]), "Real", "parameter", "fixed", "start", s["start"], f"initial value of {s['name']}")
    for u in M.get("inputs", []):
        add(u["name"], "Real", "input", "continuous", "input", u["start"], u["description"])
    for s in M["states"]:
        add(s["name"], "Real", "output", "continuous", "state", None, s["description"])
    add("constraint_residual", "Real", "output", "continuous", "residual", None, M["residual_description"])
    return rows
