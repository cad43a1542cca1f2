"""Plant FMUs for the co-simulation examples and tests, and SSP packaging.

- :func:`build_linear_plant`: ``x' = A x + b u`` (two states) as a C FMU compiled
  here with gcc (source: ``linear_plant.c``); declares
  ``maxOutputDerivativeOrder = 2`` and ``canInterpolateInputs``.
- :func:`build_lag_plant`: ``w' = -w + g u`` made with pythonfmu (exact
  exponential step for a held input; no derivatives in or out).
- :func:`build_source`, :func:`build_scalar_plant`: scalar C FMUs (source: ``scalar.c``), a source
  ``y = expr(t)`` and a plant ``x' = a x + b u, y = x, z = c x + d u + e`` stepped exactly, each
  with or without output derivatives, input interpolation and rollback (test cases for the master).
- :func:`build_expression_fmu`: a C FMU whose states, outputs and output derivatives are C expressions
  (source: ``expression.c``), with optional discarded steps and a broken rollback (attack cases).
- :func:`build_event_source3`: an FMI 3.0 C source whose output jumps from 0 to 1 at ``t_event``
  inside a step, returning early there where allowed (source: ``event_source3.c``).
- :func:`write_ssp`: an ``.ssp`` archive (``SystemStructure.ssd`` + the FMUs).
"""
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import escape

HERE = Path(__file__).parent

_NAMES = ("a11", "a12", "a21", "a22", "b1", "b2", "x1_0", "x2_0", "substeps")


def fmpy_headers():
    """The FMI 2.0 headers fmpy ships (its c-code folder)."""
    import fmpy

    return Path(fmpy.__file__).parent / "c-code"


def build_linear_plant(dest, name, A, b, x0, substeps=20, output_names=("y1", "y2"), input_name="u", follower=False,
                       units=None, unit_definitions=None):
    """Compile ``linear_plant.c`` into ``dest/name.fmu`` with the given matrices as start values.

    ``follower=True``: the exact index-2 follower x1 = u, x2 = -u' instead (A, b unused).
    ``units``: ``{variable: unit name}`` (the unit attribute of those variables); ``unit_definitions``:
    ``{unit name: {"m": 1, "factor": 0.01, ...} or None}``, the model description's UnitDefinitions (the
    BaseUnit's attributes; None: the name alone).
    """
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    values = [A[0][0], A[0][1], A[1][0], A[1][1], b[0], b[1], x0[0], x0[1], float(substeps)]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "binaries" / "linux64").mkdir(parents=True)
        defines = [f"-DPLANT_{key.upper()}={float(v)!r}" for key, v in zip(_NAMES, values)]
        defines.append(f"-DPLANT_FOLLOWER={int(bool(follower))}")
        subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-std=c99", "-Wall", "-Wextra", "-Werror",
                        "-DFMI2_FUNCTION_PREFIX=", f"-I{fmpy_headers()}", *defines,
                        str(HERE / "linear_plant.c"), "-o", str(tmp / "binaries" / "linux64" / f"{name}.so"), "-lm"],
                       check=True)
        units = units or {}
        unit = lambda key: f' unit="{escape(units[key])}"' if key in units else ""  # noqa: E731
        variables = []
        for vr, (key, v) in enumerate(zip(_NAMES, values)):
            variables.append(f'<ScalarVariable name="{key}" valueReference="{vr}" causality="parameter" '
                             f'variability="{"tunable" if key == "substeps" else "fixed"}"><Real start="{v!r}"'
                             f'{unit(key)}/></ScalarVariable>')
        variables.append(f'<ScalarVariable name="{input_name}" valueReference="9" causality="input" '
                         f'variability="continuous"><Real start="0.0"{unit(input_name)}/></ScalarVariable>')
        for i, out in enumerate(output_names):
            variables.append(f'<ScalarVariable name="{out}" valueReference="{10 + i}" causality="output" '
                             f'variability="continuous" initial="exact"><Real start="{values[6 + i]!r}"{unit(out)}/>'
                             '</ScalarVariable>')
        definitions = _unit_definitions(unit_definitions)
        xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{{uuid.uuid4()}}}"
  description="linear two-state plant x' = A x + b u (RK4, output derivatives)" generationTool="lsc examples/plants"
  numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true" canInterpolateInputs="true"
    maxOutputDerivativeOrder="2" canGetAndSetFMUstate="true" canSerializeFMUstate="true"/>
  {definitions}
  <ModelVariables>
    {chr(10).join('    ' + v for v in variables).strip()}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
      <Unknown index="{len(_NAMES) + 2}" dependencies=""/>
      <Unknown index="{len(_NAMES) + 3}" dependencies=""/>
    </Outputs>
  </ModelStructure>
</fmiModelDescription>
"""
        (tmp / "modelDescription.xml").write_text(xml)
        (tmp / "sources").mkdir()
        shutil.copy(HERE / "linear_plant.c", tmp / "sources")
        shutil.copy(HERE / "plant_common.h", tmp / "sources")
        return _zip_dir(tmp, dest / f"{name}.fmu")



def _unit_definitions(unit_definitions):
    """The ``<UnitDefinitions>`` element of ``{unit name: {"m": 1, "factor": 0.01, ...} or None}`` ("" if none)."""
    if not unit_definitions:
        return ""
    items = []
    for uname, base in unit_definitions.items():
        attrs = "".join(f' {k}="{v!r}"' for k, v in (base or {}).items())
        items.append(f'<Unit name="{escape(uname)}">' + (f"<BaseUnit{attrs}/>" if base is not None else "") + "</Unit>")
    return "<UnitDefinitions>" + "".join(items) + "</UnitDefinitions>"


def _package(dest, name, source_file, defines, xml):
    """Compile ``source_file`` with ``defines`` and zip it with ``xml`` into ``dest/name.fmu`` (atomically)."""
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "binaries" / "linux64").mkdir(parents=True)
        subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-std=c99", "-Wall", "-Wextra", "-Werror",
                        "-DFMI2_FUNCTION_PREFIX=", f"-I{fmpy_headers()}", f"-I{HERE}", *defines, str(HERE / source_file),
                        "-o", str(tmp / "binaries" / "linux64" / f"{name}.so"), "-lm"], check=True)
        (tmp / "modelDescription.xml").write_text(xml)
        (tmp / "sources").mkdir()
        shutil.copy(HERE / source_file, tmp / "sources")
        shutil.copy(HERE / "plant_common.h", tmp / "sources")  # the FMI functions the plants share
        return _zip_dir(tmp, dest / f"{name}.fmu")


def _scalar_xml(name, description, variables, outputs, derivatives, interpolate, rollback, initial=None,
                directional=False, definitions=""):
    """``initial``: the ``(index, dependencies)`` of the initial unknowns (default: ``outputs``);
    ``directional``: declare ``providesDirectionalDerivative``; ``definitions``: a ``<UnitDefinitions>``."""
    flags = (f'canInterpolateInputs="{str(interpolate).lower()}" maxOutputDerivativeOrder="{2 if derivatives else 0}" '
             f'canGetAndSetFMUstate="{str(rollback).lower()}" canSerializeFMUstate="{str(rollback).lower()}"'
             + (' providesDirectionalDerivative="true"' if directional else ''))
    unknowns = "".join(f'<Unknown index="{i}" dependencies="{deps}"/>' for i, deps in outputs)
    initial = unknowns if initial is None else "".join(f'<Unknown index="{i}" dependencies="{deps}"/>'
                                                       for i, deps in initial)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{{uuid.uuid4()}}}"
  description="{escape(description)}" generationTool="lsc examples/plants" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true" {flags}/>
  {definitions}
  <ModelVariables>
    {chr(10).join(variables)}
  </ModelVariables>
  <ModelStructure><Outputs>{unknowns}</Outputs>{f"<InitialUnknowns>{initial}</InitialUnknowns>" if initial else ""}</ModelStructure>
</fmiModelDescription>
"""


def build_source(dest, name, y, d1=None, d2=None, rollback=True):
    """A C source FMU ``dest/name.fmu`` whose output ``y`` is the C expression ``y`` of ``t``.

    With ``d1`` and ``d2`` (C expressions of ``t``: y' and y'') it declares
    ``maxOutputDerivativeOrder = 2`` and returns them; ``rollback`` sets ``canGetAndSetFMUstate``.
    """
    derivatives = d1 is not None
    defines = ["-DSCALAR_SOURCE=1", f"-DSCALAR_DERIVATIVES={int(derivatives)}", f"-DSOURCE_Y(t)=({y})"]
    if derivatives:
        defines += [f"-DSOURCE_D1(t)=({d1})", f"-DSOURCE_D2(t)=({d2 if d2 is not None else 0.0})"]
    variables = ['<ScalarVariable name="y" valueReference="0" causality="output" variability="continuous"><Real/>'
                 '</ScalarVariable>']
    xml = _scalar_xml(name, f"y = {y}", variables, [(1, "")], derivatives, False, rollback)
    return _package(dest, name, "scalar.c", defines, xml)


def build_scalar_plant(dest, name, a, b, c=0.0, d=0.0, e=0.0, x0=0.0, derivatives=False, interpolate=True,
                       rollback=True, directional=None, units=None, unit_definitions=None):
    """A C FMU ``dest/name.fmu`` of ``x' = a x + b u, y = x, z = c x + d u + e`` (exact steps for the
    received input polynomial); ``z`` depends on ``u`` directly when ``d != 0``.

    ``derivatives``: output derivatives of orders 1 and 2 (``maxOutputDerivativeOrder = 2``);
    ``interpolate``: ``canInterpolateInputs``; ``rollback``: ``canGetAndSetFMUstate``;
    ``directional``: None (``fmi2GetDirectionalDerivative`` refused, not declared) or a factor: declared
    and implemented as ``dz/du = factor * d`` (1: exact; another factor: an FMU whose derivatives are wrong);
    ``units``, ``unit_definitions``: the units of ``u``, ``y``, ``z`` (as in :func:`build_linear_plant`).
    """
    units = units or {}
    unit = lambda key: f' unit="{escape(units[key])}"' if key in units else ""  # noqa: E731
    values = [float(v) for v in (a, b, c, d, e, x0)]
    defines = [f"-DSCALAR_DERIVATIVES={int(bool(derivatives))}",
               "-DPLANT_PARAMETERS=" + ",".join(repr(v) for v in values)]
    if directional is not None:
        defines += ["-DSCALAR_DIRECTIONAL=1", f"-DSCALAR_DIRECTIONAL_FACTOR={float(directional)!r}"]
    variables = [f'<ScalarVariable name="{key}" valueReference="{vr}" causality="parameter" variability="fixed">'
                 f'<Real start="{v!r}"/></ScalarVariable>' for vr, (key, v) in enumerate(zip("abcde", values))]
    variables.append(f'<ScalarVariable name="x0" valueReference="5" causality="parameter" variability="fixed">'
                     f'<Real start="{values[5]!r}"/></ScalarVariable>')
    variables.append('<ScalarVariable name="u" valueReference="6" causality="input" variability="continuous">'
                     f'<Real start="0.0"{unit("u")}/></ScalarVariable>')
    variables.append('<ScalarVariable name="y" valueReference="7" causality="output" variability="continuous">'
                     f'<Real{unit("y")}/></ScalarVariable>')
    variables.append('<ScalarVariable name="z" valueReference="8" causality="output" variability="continuous">'
                     f'<Real{unit("z")}/></ScalarVariable>')
    outputs = [(8, ""), (9, "7" if values[3] != 0.0 else "")]
    description = f"x' = {a} x + {b} u, y = x, z = {c} x + {d} u + {e}"
    xml = _scalar_xml(name, description, variables, outputs, bool(derivatives), bool(interpolate), bool(rollback),
                      directional=directional is not None, definitions=_unit_definitions(unit_definitions))
    return _package(dest, name, "scalar.c", defines, xml)

_LAG = '''
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class {name}(Fmi2Slave):
    """First-order lag w' = -w + g u, exact step for an input held over the step."""

    author = "lsc examples"
    description = "first-order lag w' = -w + g u (pythonfmu)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.g = {g!r}
        self.w0 = {w0!r}
        self.u = 0.0
        self.w = {w0!r}
        self.register_variable(Real("g", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("w0", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("u", causality=Fmi2Causality.input, variability=Fmi2Variability.continuous))
        self.register_variable(Real("w", causality=Fmi2Causality.output, variability=Fmi2Variability.continuous))

    def exit_initialization_mode(self):
        self.w = self.w0

    def do_step(self, current_time, step_size):
        if not math.isfinite(self.u):
            return False
        e = math.exp(-step_size)
        self.w = e * self.w + self.g * (1.0 - e) * self.u
        return True
'''


def build_lag_plant(dest, name="LagPlant", g=0.2, w0=1.0):
    """A pythonfmu FMU of ``w' = -w + g u`` (state w, output w; w has no direct feedthrough)."""
    from pythonfmu.builder import FmuBuilder

    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / f"{name}.py"
        script.write_text(textwrap.dedent(_LAG.format(name=name, g=float(g), w0=float(w0))))
        fmu = Path(FmuBuilder.build_FMU(script, dest=dest, canGetAndSetFMUstate=True, canSerializeFMUstate=True))
    sys.modules.pop(name, None)
    # pythonfmu writes no output dependencies: w is a state (no feedthrough), say so
    with zipfile.ZipFile(fmu) as zf:
        contents = {n: zf.read(n) for n in zf.namelist()}
    xml = contents["modelDescription.xml"].decode()
    import re

    index = None
    for i, m in enumerate(re.finditer(r"<ScalarVariable\b[^>]*>", xml), start=1):
        if 'name="w"' in m.group(0):
            index = i
    xml = re.sub(r"<ModelStructure>.*</ModelStructure>|<ModelStructure\s*/>",
                 f'<ModelStructure><Outputs><Unknown index="{index}" dependencies=""/></Outputs>'
                 f'<InitialUnknowns><Unknown index="{index}"/></InitialUnknowns></ModelStructure>', xml, flags=re.S)
    contents["modelDescription.xml"] = xml.encode()
    partial = fmu.with_suffix(".part")
    with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
        for n, data in contents.items():
            zf.writestr(n, data)
    os.replace(partial, fmu)
    return fmu


FMI3_HEADERS = HERE.parent.parent / "fmu_build" / "templates" / "fmi3" / "headers"
# what an FMI 3.0 Co-Simulation test FMU without Event Mode implements: the rest are stubs (``fmi3_stubs``)
FMI3_IMPLEMENTED = frozenset({"fmi3InstantiateCoSimulation", "fmi3FreeInstance", "fmi3GetVersion",
                              "fmi3SetDebugLogging", "fmi3EnterInitializationMode", "fmi3ExitInitializationMode",
                              "fmi3Terminate", "fmi3Reset", "fmi3GetFloat64", "fmi3SetFloat64", "fmi3DoStep",
                              "fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState"})


def fmi3_stubs(path, implemented=FMI3_IMPLEMENTED):
    """Write to ``path`` a C file defining every FMI 3.0 function not in ``implemented`` as a stub that returns
    fmi3Error (3): fmpy binds every function of the standard when it loads an FMU. It is compiled as a translation
    unit of its own, without the header's prototypes; returns ``path``."""
    import re

    names = set(re.findall(r"(fmi3\w+)TYPE", (FMI3_HEADERS / "fmi3FunctionTypes.h").read_text())) - set(implemented)
    path = Path(path)
    path.write_text("".join(f"int {n}(void) {{ return 3; }}\n" for n in sorted(names)))
    return path


def build_event_source3(dest, name="EventSource", t_event=0.37, declare_early=True):
    """An FMI 3.0 Co-Simulation C FMU ``dest/name.fmu`` with the output ``y = 0`` before ``t_event``, 1 from it
    on (source: ``event_source3.c``).

    Instantiated with ``earlyReturnAllowed`` it returns early at ``t_event`` from a step that would cross it;
    ``declare_early``: ``mightReturnEarlyFromDoStep`` (False: it never returns early). State get/set work.
    """
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "binaries" / "x86_64-linux").mkdir(parents=True)
        stubs = fmi3_stubs(tmp / "stubs.c")  # the functions a master without Event Mode never calls
        subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-std=c99", "-Wall", "-Wextra", "-Werror", f"-I{FMI3_HEADERS}",
                        f"-I{HERE}", f"-DDECLARE_EARLY={int(bool(declare_early))}", f"-DT_EVENT={float(t_event)!r}",
                        str(HERE / "event_source3.c"), str(stubs), "-o", str(tmp / "binaries" / "x86_64-linux" / f"{name}.so"), "-lm"], check=True)
        stubs.unlink()
        (tmp / "modelDescription.xml").write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="{name}" instantiationToken="{{{uuid.uuid4()}}}"
  description="y = 0 before t_event, 1 from it on" generationTool="lsc examples/plants">
  <CoSimulation modelIdentifier="{name}" canGetAndSetFMUState="true" canHandleVariableCommunicationStepSize="true"
    mightReturnEarlyFromDoStep="{str(bool(declare_early)).lower()}"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Float64 name="y" valueReference="1" causality="output" variability="continuous"/>
    <Float64 name="t_event" valueReference="2" causality="parameter" variability="fixed" start="{float(t_event)!r}"/>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="1" dependencies=""/>
  </ModelStructure>
</fmiModelDescription>
""")
        (tmp / "sources").mkdir()
        shutil.copy(HERE / "event_source3.c", tmp / "sources")
        shutil.copy(HERE / "source3_common.h", tmp / "sources")  # the FMI functions the sources share
        return _zip_dir(tmp, dest / f"{name}.fmu")


def _zip_dir(folder, out):
    """``folder``'s files zipped into ``out`` (written to a temporary file, then renamed: never a broken FMU)."""
    partial = out.with_name(f".{out.name}.part")
    with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
        for f in sorted(folder.rglob("*")):
            if f.is_file():
                zf.write(f, f.relative_to(folder).as_posix())
    os.replace(partial, out)
    return out


def write_ssp(path, name, components, connections):
    """Write ``path`` (.ssp): ``components`` {name: fmu_path}, ``connections`` [("a.y", "b.u"), ...]."""
    from fmpy import read_model_description

    path = Path(path)
    elements = []
    for comp, fmu in components.items():
        md = read_model_description(str(fmu))
        connectors = "".join(
            f'<ssd:Connector name="{escape(v.name)}" kind="{v.causality}"><ssc:Real/></ssd:Connector>'
            for v in md.modelVariables if v.causality in ("input", "output") and v.type == "Real")
        elements.append(f'<ssd:Component name="{comp}" type="application/x-fmu-sharedlibrary" '
                        f'source="resources/{comp}.fmu"><ssd:Connectors>{connectors}</ssd:Connectors></ssd:Component>')
    links = []
    for a, b in connections:
        (ea, ca), (eb, cb) = a.split(".", 1), b.split(".", 1)
        links.append(f'<ssd:Connection startElement="{ea}" startConnector="{escape(ca)}" '
                     f'endElement="{eb}" endConnector="{escape(cb)}"/>')
    ssd = f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
  xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0" name="{name}">
  <ssd:System name="{name}">
    <ssd:Elements>
      {chr(10).join(elements)}
    </ssd:Elements>
    <ssd:Connections>
      {chr(10).join(links)}
    </ssd:Connections>
  </ssd:System>
</ssd:SystemStructureDescription>
"""
    partial = path.with_suffix(".part")
    with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("SystemStructure.ssd", ssd)
        for comp, fmu in components.items():
            zf.write(fmu, f"resources/{comp}.fmu")
    os.replace(partial, path)
    return path


_COUNTER = '''
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real


class Counter(Fmi2Slave):
    """count = round(t / period) (Integer), odd = count is odd (Boolean), at each communication point."""

    author = "lsc examples"
    description = "an Integer and a Boolean output (pythonfmu)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.period = 0.1
        self.count = 0
        self.odd = False
        self.register_variable(Real("period", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Integer("count", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("odd", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete))

    def do_step(self, current_time, step_size):
        self.count = int(round((current_time + step_size) / self.period))
        self.odd = self.count % 2 == 1
        return True


class Sink(Fmi2Slave):
    """y = 10 n + (1 if b else 0) + (100 if on else 0) from the inputs held over the step (Real output)."""

    author = "lsc examples"
    description = "Integer and Boolean inputs, a Boolean parameter (pythonfmu)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.n = 0
        self.b = False
        self.on = True
        self.y = 0.0
        self.register_variable(Integer("n", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("b", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("on", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("y", causality=Fmi2Causality.output, variability=Fmi2Variability.continuous))

    def do_step(self, current_time, step_size):
        self.y = 10.0 * self.n + (1.0 if self.b else 0.0) + (100.0 if self.on else 0.0)
        return True
'''


def build_typed_pair(dest):
    """Two pythonfmu FMUs exchanging an Integer and a Boolean: ``Counter`` (outputs ``count``, ``odd``)
    and ``Sink`` (inputs ``n``, ``b``, Boolean parameter ``on``, Real output ``y``); returns their paths."""
    from pythonfmu.builder import FmuBuilder

    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name in ("Counter", "Sink"):
        with tempfile.TemporaryDirectory() as tmp:
            script = Path(tmp) / f"{name}.py"
            head, counter, sink = _COUNTER.partition("\n\nclass Sink")[0].partition("class Counter")[0], \
                "class Counter" + _COUNTER.split("class Counter", 1)[1].split("\n\nclass Sink")[0], \
                "class Sink" + _COUNTER.split("class Sink", 1)[1]
            body = head + (counter if name == "Counter" else sink)
            script.write_text(textwrap.dedent(body))
            paths[name] = Path(FmuBuilder.build_FMU(script, dest=dest, canGetAndSetFMUstate=True,
                                                    canSerializeFMUstate=True))
        sys.modules.pop(name, None)
    return paths["Counter"], paths["Sink"]


def _c_array(rows):
    return ", ".join(repr(float(v)) for row in rows for v in (row if hasattr(row, "__len__") else [row]))


def build_lti(dest, name, A, B, C, D, x0, inputs, outputs, derivatives=True, interpolate=True, rollback=True,
              description="linear block x' = A x + B u, y = C x + D u"):
    """A C FMU ``dest/name.fmu`` of ``x' = A x + B u, y = C x + D u`` (source: ``lti.c``), stepped exactly
    for the received input polynomial (so every error of a co-simulation with it is the master's).

    ``inputs``, ``outputs``: the variables' names; an output depends directly on the inputs whose column
    of ``D`` is nonzero in its row (declared in the model structure). ``derivatives``: output derivatives
    of orders 1 and 2 (``maxOutputDerivativeOrder = 2``); ``interpolate``: ``canInterpolateInputs``;
    ``rollback``: ``canGetAndSetFMUstate``. The Integer output ``nDoStep`` counts the fmi2DoStep calls.
    """
    import numpy as np

    A, B, C, D = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B, C, D))
    nx, nu, ny = A.shape[0], len(inputs), len(outputs)
    if A.shape != (nx, nx) or B.shape != (nx, nu) or C.shape != (ny, nx) or D.shape != (ny, nu) or len(x0) != nx:
        raise ValueError(f"`A`, `B`, `C`, `D`, `x0` must be ({nx}, {nx}), ({nx}, {nu}), ({ny}, {nx}), ({ny}, {nu}), "
                         f"({nx},); found {A.shape}, {B.shape}, {C.shape}, {D.shape}, ({len(x0)},).")
    defines = [f"-DLTI_NX={nx}", f"-DLTI_NU={nu}", f"-DLTI_NY={ny}", f"-DLTI_A={_c_array(A)}",
               f"-DLTI_B={_c_array(B)}", f"-DLTI_C={_c_array(C)}", f"-DLTI_D={_c_array(D)}",
               f"-DLTI_X0={_c_array(x0)}"]
    variables = [f'<ScalarVariable name="{escape(u)}" valueReference="{j}" causality="input" '
                 f'variability="continuous"><Real start="0.0"/></ScalarVariable>' for j, u in enumerate(inputs)]
    y0 = C @ np.asarray(x0, dtype=float)
    variables += [f'<ScalarVariable name="{escape(y)}" valueReference="{nu + i}" causality="output" '
                  f'variability="continuous" initial="exact"><Real start="{float(y0[i])!r}"/></ScalarVariable>'
                  if not D[i].any() else
                  f'<ScalarVariable name="{escape(y)}" valueReference="{nu + i}" causality="output" '
                  f'variability="continuous"><Real/></ScalarVariable>' for i, y in enumerate(outputs)]
    variables.append('<ScalarVariable name="nDoStep" valueReference="0" causality="output" variability="discrete" '
                     'initial="exact"><Integer start="0"/></ScalarVariable>')
    outs = [(nu + i + 1, " ".join(str(j + 1) for j in range(nu) if D[i, j] != 0.0)) for i in range(ny)]
    outs.append((nu + ny + 1, ""))
    # outputs with a start value (no feedthrough) are known before initialization; the others are computed
    initial = [(index, deps) for (index, deps), i in zip(outs, range(ny)) if D[i].any()]
    xml = _scalar_xml(name, description, variables, outs, derivatives, interpolate, rollback, initial)
    return _package(dest, name, "lti.c", defines, xml)


def build_expression_fmu(dest, name, outputs, inputs=(), states=(), deriv="", derivatives=None, dependencies=None,
                         parameters=None, interpolate=True, rollback=True, discard=None, substep=1e-3,
                         fake_rollback=False):
    """A C FMU ``dest/name.fmu`` (source: ``expression.c``) whose behaviour is given by C expressions.

    ``outputs``: ``{name: expression}`` (at most 3) of ``t``, the states ``x[i]``, the inputs ``U(i)``
    and the parameters ``P(i)``; ``inputs``: input names (at most 3); ``states``: the states' start
    values; ``deriv``: C statements setting ``dx[i]`` (integrated by RK4 on substeps of at most
    ``substep``, the inputs on the polynomial received); ``derivatives``: ``{output: (d1, d2)}``
    expressions of the output's first and second derivatives (``DU(i, j)``: input ``i``'s derivative of
    order ``j`` received; ``maxOutputDerivativeOrder = 2``, the other outputs refuse); ``dependencies``:
    ``{output: [inputs]}`` as declared in the model description (default: every input for an output whose
    expression reads ``U(``, else none; ``None`` as a value: the attribute left out); ``parameters``:
    ``{name: start}`` (at most 4, tunable); ``discard``: a C condition of ``t`` and ``h`` under which a
    step is discarded; ``interpolate``, ``rollback``: ``canInterpolateInputs``, ``canGetAndSetFMUstate``;
    ``fake_rollback``: ``fmi2SetFMUstate`` returns fmi2OK and restores nothing (a broken FMU).
    """
    inputs, names = list(inputs), list(outputs)
    parameters = dict(parameters or {})
    derivatives = dict(derivatives or {})
    if len(names) > 3 or len(inputs) > 3 or len(parameters) > 4 or len(states) > 4:
        raise ValueError("at most 3 outputs, 3 inputs, 4 parameters and 4 states")
    defines = [f"-DEX_NX={len(states)}", f"-DEX_NU={len(inputs)}", f"-DEX_NY={len(names)}",
               "-DEX_X0=" + (",".join(repr(float(v)) for v in states) or "0.0"),
               "-DEX_P0=" + ",".join(repr(float(v)) for v in (list(parameters.values()) + [0.0] * 4)[:4]),
               f"-DEX_DERIV={deriv}", f"-DEX_SUBSTEP={float(substep)!r}",
               f"-DEX_DERIVATIVES={2 if derivatives else 0}", f"-DEX_FAKE_ROLLBACK={int(bool(fake_rollback))}",
               f"-DEX_HASD={sum(1 << k for k, n in enumerate(names) if n in derivatives)}"]
    for k, n in enumerate(names):
        defines.append(f"-DEX_Y{k}=({outputs[n]})")
        if n in derivatives:
            d1, d2 = derivatives[n]
            defines += [f"-DEX_D1_{k}=({d1})", f"-DEX_D2_{k}=({d2})"]
    if discard is not None:
        defines.append(f"-DEX_DISCARD(t,h)=({discard})")
    variables = [f'<ScalarVariable name="{escape(u)}" valueReference="{i}" causality="input" '
                 'variability="continuous"><Real start="0.0"/></ScalarVariable>' for i, u in enumerate(inputs)]
    variables += [f'<ScalarVariable name="{escape(n)}" valueReference="{10 + k}" causality="output" '
                  'variability="continuous"><Real/></ScalarVariable>' for k, n in enumerate(names)]
    variables += [f'<ScalarVariable name="{escape(n)}" valueReference="{20 + k}" causality="parameter" '
                  f'variability="tunable"><Real start="{float(v)!r}"/></ScalarVariable>'
                  for k, (n, v) in enumerate(parameters.items())]
    unknowns = []
    for k, n in enumerate(names):
        deps = (dependencies or {}).get(n, inputs if "U(" in outputs[n] else [])
        attr = "" if deps is None else f' dependencies="{" ".join(str(inputs.index(u) + 1) for u in deps)}"'
        unknowns.append(f'<Unknown index="{len(inputs) + k + 1}"{attr}/>')
    flags = (f'canInterpolateInputs="{str(bool(interpolate)).lower()}" '
             f'maxOutputDerivativeOrder="{2 if derivatives else 0}" '
             f'canGetAndSetFMUstate="{str(bool(rollback)).lower()}" '
             f'canSerializeFMUstate="{str(bool(rollback)).lower()}"')
    description = "; ".join(f"{n} = {e}" for n, e in outputs.items()) + (f"; {deriv}" if deriv else "")
    xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{{uuid.uuid4()}}}"
  description="{escape(description, {'"': '&quot;'})}" generationTool="lsc examples/plants" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true" {flags}/>
  <ModelVariables>
    {chr(10).join(variables)}
  </ModelVariables>
  <ModelStructure><Outputs>{"".join(unknowns)}</Outputs></ModelStructure>
</fmiModelDescription>
"""
    return _package(dest, name, "expression.c", defines, xml)
