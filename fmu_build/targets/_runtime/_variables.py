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
    for row in rt.model.MODEL["variables"]:
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
