"""The FMU's interface: one table of variables, from which every artefact of a build is written.

A row (`Variable`) says everything the FMU declares about one variable:
name, type, value reference, causality, variability, initial, start value,
unit, description, the state it is the derivative of, the knowns an output
depends on, and its *role*: what the FMU does with it (the stabilization
rate, a parameter, a state's start value, an input, a state, ...). The
targets lay the table out once from the spec and the completion
(`native_interface`, `pythonfmu_interface`), and write from it:

- the FMI 2.0 and 3.0 model descriptions (`Interface.rows` for
  `fmu_build._description` and `fmu_build._description3`; `Interface.fmi3`
  gives the FMI 3.0 value references);
- the value-reference ``#define`` lines, the role of each value reference and
  the start values in the native C model header (`Interface.c_defines`,
  `Interface.c_arrays`);
- the pythonfmu registration inside the FMU (`Interface.registration`, read by
  `fmu_build.targets._runtime._variables.register_variables`).
"""

from dataclasses import asdict, dataclass, field, replace

from .spec import METHODS
from .targets._runtime._variables import EXACT, start_name

__all__ = ["C_BLOCKS", "Interface", "Variable", "native_interface", "pythonfmu_interface"]

# The native C core's Real variables, one block per role in this order. The header defines the first value
# reference of each block (VR_<name>) and the role of every value reference (VR_KIND: the index of its role here).
C_BLOCKS = (("lambda", "LAMBDA"), ("parameter", "PAR"), ("start", "X0"), ("input", "U"), ("state", "X"),
            ("output", "Y"), ("residual", "RES"), ("derivative", "DX"), ("constant", "K"))

_RESIDUAL = "norm of the constraint residual Z2^T (F x - g): distance from the solution manifold"
_PROJECT = "project the initial state onto the solution manifold before the first step"


@dataclass(frozen=True)
class Variable:
    """One variable of an FMU: what its model description declares and the role it plays in the FMU.

    ``role`` is one of 'lambda', 'parameter', 'start', 'input', 'state',
    'output', 'residual', 'derivative', 'constant', 'option' (a setting of
    the FMU: ``project_initial``, the pythonfmu solver, ...) or 'time' (the
    FMI 3.0 independent variable). ``dependencies`` (names) is None when the
    description states none. ``output_derivatives`` says whether the native
    FMU returns the time derivatives of a custom output.
    """

    name: str
    type: str
    vr: int
    causality: str
    variability: str
    role: str
    initial: str = None
    start: object = None
    unit: str = ""
    description: str = ""
    derivative: str = None
    dependencies: tuple = None
    output_derivatives: bool = False


@dataclass(frozen=True)
class Interface:
    """The table of an FMU's variables, in the order of its model description.

    Examples
    --------
    >>> table = Interface((Variable("lambda", "Real", 0, "parameter", "tunable", "lambda", start=1.0),
    ...                    Variable("x", "Real", 1, "output", "continuous", "state")))
    >>> table["x"].vr, [v.name for v in table.replace("x", name="y")]
    (1, ['lambda', 'y'])
    """

    variables: tuple = field(default_factory=tuple)

    def __iter__(self):
        return iter(self.variables)

    def __len__(self):
        return len(self.variables)

    def __getitem__(self, name):
        for v in self.variables:
            if v.name == name:
                return v
        raise KeyError(name)

    def replace(self, variable, /, **changes):
        """The table with the row of the variable named `variable` changed (`dataclasses.replace`)."""
        self[variable]  # a KeyError names a variable the table does not have
        return Interface(tuple(replace(v, **changes) if v.name == variable else v for v in self.variables))

    def of_role(self, role):
        """The variables of one role, in table order."""
        return [v for v in self.variables if v.role == role]

    def rows(self):
        """The variables as the dicts `fmu_build._description.model_description` (and ``3``) take."""
        out = []
        for v in self.variables:
            row = asdict(v)
            del row["role"], row["output_derivatives"]
            out.append(row)
        return out

    def fmi3(self):
        """The table with FMI 3.0 value references (unique over all types) and the independent variable time.

        The Real variables keep theirs (``0 .. NR - 1``); the others follow in table order (``NR, ...``),
        then ``time``.
        """
        nr = self._real_count()
        others = [v for v in self.variables if v.type != "Real"]
        moved = {id(v): nr + i for i, v in enumerate(others)}
        time = Variable("time", "Real", nr + len(others), "independent", "continuous", "time", unit="s",
                        description="simulation time")
        return Interface((time, *(replace(v, vr=moved.get(id(v), v.vr)) for v in self.variables)))

    def _real_count(self):
        return sum(1 for v in self.variables if v.type == "Real")

    def c_defines(self):
        """The value-reference lines of the native C model header (the core's FMI 2.0 numbering).

        ``VR_<block>`` is the first value reference of each block of `C_BLOCKS`
        (of an empty block: where it would start), ``NR`` the number of Real
        variables, ``VRB_PROJECT`` the Boolean ``project_initial``, and
        ``VR3_PROJECT``, ``VR3_TIME`` its and time's FMI 3.0 value references.
        Raises ValueError when a block is not one run of consecutive value
        references.
        """
        kinds = self._c_kinds()
        lines, start = [], 0
        for kind, (role, cname) in enumerate(C_BLOCKS):
            block = [i for i, k in enumerate(kinds) if k == kind]
            if block and block != list(range(block[0], block[0] + len(block))):
                raise ValueError(f"the {role} variables must have consecutive value references; found {block}")
            start = block[0] if block else start
            lines.append(f"#define VR_{cname} {start}")
            start += len(block)
        three = self.fmi3()
        lines += [f"#define NR {len(kinds)}", f"#define VRB_PROJECT {self['project_initial'].vr}",
                  f"#define VR3_PROJECT {three['project_initial'].vr}u", f"#define VR3_TIME {three['time'].vr}u"]
        return lines

    def _c_kinds(self):
        """The block (index in `C_BLOCKS`) of each Real value reference 0, 1, ..."""
        reals = sorted((v for v in self.variables if v.type == "Real"), key=lambda v: v.vr)
        if [v.vr for v in reals] != list(range(len(reals))):
            raise ValueError(f"the Real value references must be 0 .. {len(reals) - 1}; found {[v.vr for v in reals]}")
        roles = [role for role, _ in C_BLOCKS]
        for v in reals:
            if v.role not in roles:
                raise ValueError(f"the Real variable {v.name!r} has no block in the C core (role {v.role!r})")
        return [roles.index(v.role) for v in reals]

    def c_arrays(self):
        """The constant arrays of the native C model header: ``(name, values, C type)`` of each.

        The block of every Real value reference (``VR_KIND``, read by
        ``vr_kind``), the start values of the parameters in ``f``
        (``PAR_START``; ``PAR_TUNABLE`` which of them are tunable), of the
        states (``X_START``) and the inputs (``U_START``), the values of the
        fixed parameters (``K_VALUE``) and which custom outputs give their
        derivatives (``OUT_LINEAR``).
        """
        starts = {role: [v.start for v in self.of_role(role)] for role in ("parameter", "start", "input", "constant")}
        return [("VR_KIND", self._c_kinds(), "signed char"), ("PAR_START", starts["parameter"], "double"),
                ("PAR_TUNABLE", [int(v.variability == "tunable") for v in self.of_role("parameter")], "int"),
                ("X_START", starts["start"], "double"), ("U_START", starts["input"], "double"),
                ("K_VALUE", starts["constant"], "double"),
                ("OUT_LINEAR", [int(v.output_derivatives) for v in self.of_role("output")], "int")]

    def registration(self):
        """What the pythonfmu runtime registers, in order: name, type, role, causality, variability, start,
        description of each variable (plain data for the generated model module)."""
        keys = ("name", "type", "vr", "role", "causality", "variability", "start", "description")
        return [{k: getattr(v, k) for k in keys} for v in self.variables]


def _parameter(spec, name):
    return next(p for p in spec.parameters if p["name"] == name)


def _output_has_derivatives(expr, spec):
    """True when the native FMU can give an output's derivatives: linear in the states, free of t and inputs."""
    import sympy

    states = {s["name"] for s in spec.states}
    free = {str(s) for s in expr.free_symbols}
    if spec.t in expr.free_symbols or free & set(spec.input_symbols):
        return False
    syms = [s for s in expr.free_symbols if str(s) in states]
    try:
        return all(sympy.simplify(sympy.diff(expr, a, b)) == 0 for a in syms for b in syms)
    except Exception:  # pragma: no cover - sympy cannot decide: no derivative offered
        return False


def native_interface(spec, *, fpars, kpars, lam_tunable):
    """The variables of a native FMU, laid out in the blocks of `C_BLOCKS` (Real) and ``project_initial``.

    `fpars`: the parameters the C reads at run time (those in ``f``), `kpars`: those fixed at their spec
    values (in ``A`` or ``B``), `lam_tunable`: whether ``lambda`` is a tunable parameter.
    """
    values = {spec.symbols[name]: _parameter(spec, name)["value"] for name in kpars}
    state_names = [s["name"] for s in spec.states]
    f_inputs = sorted({str(s) for s in spec.f.free_symbols} & set(spec.input_symbols))
    rows = []

    def add(name, causality, variability, role, **kw):
        rows.append(Variable(name, "Real", len(rows), causality, variability, role, **kw))

    add("lambda", "parameter" if lam_tunable else "local", "tunable" if lam_tunable else "constant", "lambda",
        initial="exact", start=float(spec.lam), unit="1/s",
        description="stabilization rate lam (1/time): off-manifold errors decay like exp(-lam t)" + {
            "alternative": "", "standard": "; unused by the standard completion",
            "stabilized": "; a constant of this native FMU (the stabilized completion is not affine in lambda: "
                          "its matrices are computed at build time)"}[spec.method])
    for name in fpars:
        p = _parameter(spec, name)
        add(name, "parameter", "tunable" if p["tunable"] else "fixed", "parameter", initial="exact",
            start=float(p["value"]), unit=p["unit"], description=p["description"])
    for s in spec.states:
        add(start_name(s["name"]), "parameter", "fixed", "start", initial="exact", start=float(s["start"]),
            unit=s["unit"], description=f"initial value of {s['name']}")
    for u in spec.inputs:
        add(u["name"], "input", "continuous", "input", start=float(u["start"]), unit=u["unit"],
            description=u["description"])
    for s in spec.states:
        add(s["name"], "output", "continuous", "state", unit=s["unit"], description=s["description"], dependencies=())
    for o in spec.outputs:
        linear = _output_has_derivatives(o["expr"].subs(values), spec)
        reads = tuple(sorted(str(x) for x in o["expr"].free_symbols
                             if str(x) in spec.input_symbols or str(x) in state_names))
        add(o["name"], "output", "continuous", "output", unit=o["unit"], dependencies=reads,
            description=o["description"] + (" (output derivatives available)" if linear else ""),
            output_derivatives=linear)
    add("constraint_residual", "output", "continuous", "residual", description=_RESIDUAL,
        dependencies=tuple(state_names + f_inputs))
    for s in spec.states:
        add(f"der({s['name']})", "local", "continuous", "derivative", derivative=s["name"],
            unit=f"{s['unit']}/s" if s["unit"] else "", description=f"x' = G x + g of {s['name']}",
            dependencies=tuple(state_names + f_inputs))
    for name in kpars:
        p = _parameter(spec, name)
        add(name, "local", "constant", "constant", initial="exact", start=float(p["value"]), unit=p["unit"],
            description=f"{p['description']} (enters A or B: fixed at its spec value in this native FMU)")
    # FMI 2.0 numbers value references per type: the one Boolean is 0
    rows.append(Variable("project_initial", "Boolean", 0, "parameter", "fixed", "option", initial="exact",
                         start=False, description=_PROJECT))
    return Interface(tuple(rows))


_SOLVERS_ALL = ("integrator per step: 0 RK45, 1 DOP853, 2 Radau, 3 BDF, 4 exact (matrix exponential; constant "
                "coefficients only), 5 Magnus4 (fourth-order Magnus step, two evaluations of the completion per "
                "step; time-varying coefficients)")


def _pythonfmu_settings(add, lam, method, solver_start, solver_description):
    """The settings every pythonfmu FMU declares first: lambda, method, solver, rtol, atol, project_initial."""
    add("lambda", "Real", "parameter", "tunable", "lambda", start=lam, unit="1/s",
        description="stabilization rate lam (1/time): off-manifold errors decay like exp(-lam t); unused by 'standard'")
    add("method", "Integer", "parameter", "fixed", "option", start=METHODS.index(method),
        description="completion: " + ", ".join(f"{i} {m}" for i, m in enumerate(METHODS)))
    add("solver", "Integer", "parameter", "tunable", "option", start=solver_start, description=solver_description)
    add("rtol", "Real", "parameter", "tunable", "option", start=1e-6, description="relative tolerance of the integrator")
    add("atol", "Real", "parameter", "tunable", "option", start=1e-9, description="absolute tolerance of the integrator")
    add("project_initial", "Boolean", "parameter", "fixed", "option", start=False, description=_PROJECT)


def sparse_pythonfmu_settings(lam):
    """The registration rows of a sparse model's pythonfmu FMU before its states (`Interface.registration`
    format) and the residual's description: the FMU makes the rows of its n states when it loads
    (`fmu_build.targets._runtime._variables.sparse_rows`), too many to write into its model module."""
    rows = []

    def add(name, kind, causality, variability, role, **kw):
        rows.append(Variable(name, kind, len(rows), causality, variability, role, **kw))

    _pythonfmu_settings(add, lam, "alternative", 0, "integrator per step: 0 RK45, 1 DOP853")
    return Interface(tuple(rows)).registration(), _RESIDUAL


def pythonfmu_interface(spec, *, exact_capable):
    """The variables of a pythonfmu FMU; value references in registration order (pythonfmu numbers all types
    in one sequence). `exact_capable`: constant coefficients, where the solver starts as 'exact'."""
    rows = []

    def add(name, kind, causality, variability, role, **kw):
        rows.append(Variable(name, kind, len(rows), causality, variability, role, **kw))

    _pythonfmu_settings(add, spec.lam, spec.method, EXACT if exact_capable else 0, _SOLVERS_ALL)
    for p in spec.parameters:
        add(p["name"], "Real", "parameter", "tunable" if p["tunable"] else "fixed", "parameter", start=p["value"],
            unit=p["unit"], description=p["description"])
    for s in spec.states:
        add(start_name(s["name"]), "Real", "parameter", "fixed", "start", start=s["start"], unit=s["unit"],
            description=f"initial value of {s['name']}")
    for u in spec.inputs:
        add(u["name"], "Real", "input", "continuous", "input", start=u["start"], unit=u["unit"],
            description=u["description"])
    for s in spec.states:  # no direct feedthrough
        add(s["name"], "Real", "output", "continuous", "state", unit=s["unit"], description=s["description"],
            dependencies=())
    for o in spec.outputs:  # a custom output that reads an input depends on it directly (feedthrough)
        add(o["name"], "Real", "output", "continuous", "output", unit=o["unit"], description=o["description"],
            dependencies=tuple(sorted(str(s) for s in o["expr"].free_symbols if str(s) in spec.input_symbols)))
    add("constraint_residual", "Real", "output", "continuous", "residual", description=_RESIDUAL, dependencies=())
    return Interface(tuple(rows))
