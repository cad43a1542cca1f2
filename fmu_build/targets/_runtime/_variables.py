"""The FMU's variables: their enumerations, names and registration with pythonfmu."""

METHODS = ("standard", "stabilized", "alternative")
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


def register_variables(rt, slave, solver_start):
    """Register the FMU's variables with the pythonfmu `slave`, reading and writing the runtime `rt`.

    The order of registration gives the value references: it is the order of
    the model description. Returns ``({vr: input name}, {vr: state index})``.
    """
    from pythonfmu import Boolean, Fmi2Causality, Fmi2Variability, Integer, Real

    M = rt.model.MODEL
    par, out, inp = Fmi2Causality.parameter, Fmi2Causality.output, Fmi2Causality.input
    fixed, tunable, cont = Fmi2Variability.fixed, Fmi2Variability.tunable, Fmi2Variability.continuous
    reg = slave.register_variable
    reg(Real("lambda", causality=par, variability=tunable, start=M["lam"],
             description="stabilization rate lam (1/time): off-manifold errors decay like exp(-lam t); unused by 'standard'",
             getter=lambda: rt.values["lambda"], setter=lambda v: rt._set("lambda", v)))
    reg(Integer("method", causality=par, variability=fixed, start=METHODS.index(M["method"]),
                description="completion: 0 standard, 1 stabilized, 2 alternative",
                getter=lambda: rt.values["method"], setter=lambda v: rt._set("method", v)))
    reg(Integer("solver", causality=par, variability=tunable, start=solver_start,
                description="integrator per step: 0 RK45, 1 DOP853, 2 Radau, 3 BDF, 4 exact (matrix exponential; "
                            "constant coefficients only), 5 Magnus4 (fourth-order Magnus step, two evaluations of "
                            "the completion per step; time-varying coefficients)",
                getter=lambda: rt.values["solver"], setter=lambda v: rt._set("solver", v)))
    reg(Real("rtol", causality=par, variability=tunable, start=1e-6, description="relative tolerance of the integrator",
             getter=lambda: rt.values["rtol"], setter=lambda v: rt._set("rtol", v)))
    reg(Real("atol", causality=par, variability=tunable, start=1e-9, description="absolute tolerance of the integrator",
             getter=lambda: rt.values["atol"], setter=lambda v: rt._set("atol", v)))
    reg(Boolean("project_initial", causality=par, variability=fixed, start=False,
                description="project the initial state onto the solution manifold before the first step",
                getter=lambda: rt.values["project_initial"], setter=lambda v: rt._set("project_initial", v)))
    for p in M["parameters"]:
        rt.values[p["name"]] = p["value"]
        reg(Real(p["name"], causality=par, variability=tunable if p["tunable"] else fixed, start=p["value"],
                 description=p["description"], getter=lambda name=p["name"]: rt.values[name],
                 setter=lambda v, name=p["name"]: rt._set(name, v)))
    for s in M["states"]:
        key = start_name(s["name"])
        rt.values[key] = s["start"]
        reg(Real(key, causality=par, variability=fixed, start=s["start"], description=f"initial value of {s['name']}",
                 getter=lambda key=key: rt.values[key], setter=lambda v, key=key: rt._set(key, v)))
    input_of_vr = {}
    for u in M.get("inputs", []):
        var = Real(u["name"], causality=inp, variability=cont, start=u["start"], description=u["description"],
                   getter=lambda name=u["name"]: rt.inputs[name].value,
                   setter=lambda v, name=u["name"]: rt._set_input(name, v))
        reg(var)
        input_of_vr[var.value_reference] = u["name"]
    state_of_vr = {}
    for i, s in enumerate(M["states"]):
        var = Real(s["name"], causality=out, variability=cont, description=s["description"],
                   getter=lambda i=i: float(rt.x[i]))
        reg(var)
        state_of_vr[var.value_reference] = i
    for function, o in zip(getattr(rt.model, "OUTPUTS", []), M.get("outputs", [])):
        reg(Real(o["name"], causality=out, variability=cont, description=o["description"],
                 getter=lambda function=function: rt._output(function)))
    reg(Real("constraint_residual", causality=out, variability=cont,
             description="norm of the constraint residual Z2^T (F x - g): distance from the solution manifold",
             getter=rt._residual_norm))
    return input_of_vr, state_of_vr
