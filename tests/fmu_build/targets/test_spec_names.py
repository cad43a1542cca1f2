"""Names the build generates never collide with the spec's names (fmu_build.targets._pythonfmu_source)."""
import json
import subprocess
import sys

import numpy as np
import pytest
import sympy

import lsc  # noqa: F401  (the build needs it)
from fmu_build import SpecError, build_fmu, parse_spec
from fmu_build.targets._pythonfmu_source import _jet_source, _outputs_source

from tests.support import SUPPORT


def _collision_spec(pname="p__1"):
    """x' = p__1 with an input p: the parameter is named like the input's first derivative."""
    spec = {"model": {"name": "Collide"}, "states": {"x": {}},
            "parameters": {"q": {"value": 3.5}}, "inputs": {"p": {"unit": "m"}},
            "equations": {"A": [[1]], "B": [[0]], "f": ["q + 0*p"]}}
    parsed = parse_spec(spec)
    # the parser refuses the name `p__1` (see test_spec_errors): rename after parsing to see that
    # the generated code alone keeps the names apart as well
    q, new = parsed.symbols["q"], sympy.Symbol(pname, real=True)
    parsed.symbols = {pname: new}
    parsed.parameters[0]["name"] = pname
    parsed.f = parsed.f.xreplace({q: new})
    return parsed


def test_the_parser_refuses_names_of_the_generated_pattern():
    for name in ("p__1", "_lsc_params", "_LSCx", "a__b"):
        spec = {"model": {"name": "M"}, "states": {"x": {}}, "parameters": {name: 1.0},
                "equations": {"A": [[1]], "B": [[1]]}}
        with pytest.raises(SpecError, match=f"parameters.{name}: '{name}' is reserved"):
            parse_spec(spec)


@pytest.mark.parametrize("pname", ["p__1", "p__0", "out", "order", "np", "math", "float", "abs"])
def test_generated_jet_code_keeps_parameter_values(pname):
    # a parameter named like a local or a module of the generated code must keep its value
    spec = _collision_spec(pname)
    source = _jet_source("f_jet", spec.f, spec.t, [pname], 3, (1,), spec.input_symbols)
    namespace = {}
    exec(compile("import math\nimport numpy as np\n" + source, "<jet>", "exec"), namespace)
    inputs = {"p": np.array([0.8, 0.8, 0.0, 0.0])}  # p = 0.8 t: p' = 0.8
    jet = namespace["f_jet"](0.5, {pname: 3.5}, 1, inputs)
    np.testing.assert_array_equal(jet, [[3.5], [0.0]])


def test_generated_output_code_keeps_names_apart():
    spec = parse_spec({"model": {"name": "M"}, "states": {"x": {}}, "parameters": {"a": 2.0},
                       "inputs": {"w": {}}, "equations": {"A": [[1]], "B": [[1]]},
                       "outputs": {"y": "a*x + w + abs(x)"}})
    # rename to names of the generated code's own locals and builtins
    x, a, w = sympy.Symbol("x", real=True), spec.symbols["a"], spec.input_symbols["w"]
    names = {x: sympy.Symbol("float", real=True), a: sympy.Symbol("_lsc_x", real=True), w: sympy.Symbol("abs", real=True)}
    spec.states[0]["name"], spec.parameters[0]["name"], spec.inputs[0]["name"] = "float", "_lsc_x", "abs"
    spec.outputs[0]["expr"] = spec.outputs[0]["expr"].xreplace(names)
    namespace = {}
    exec(compile("import math\nimport numpy as np\n" + _outputs_source(spec), "<outputs>", "exec"), namespace)
    value = namespace["OUTPUTS"][0](0.0, np.array([-3.0]), {"_lsc_x": 2.0}, {"abs": 0.25})
    assert value == 2.0 * -3.0 + 0.25 + 3.0


def test_fmu_with_a_parameter_named_like_an_input_derivative(tmp_path):
    # x' = p__1 = 3.5 from x(0) = 0 while the input p = 0.8 t is fed: x(1) = 3.5 exactly
    pytest.importorskip("pythonfmu")
    pytest.importorskip("fmpy")
    fmu = build_fmu(_collision_spec(), tmp_path)
    dt, steps = 0.1, 10
    scenario = {"fmu": str(fmu), "dt": dt, "steps": steps, "outputs": ["x"],
                "start_values": {"rtol": 1e-10, "atol": 1e-12},
                "input_series": {"p": (0.8 * dt * np.arange(steps)).tolist()}}
    out = subprocess.run([sys.executable, str(SUPPORT / "fmu_runner.py")], input=json.dumps(scenario), capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["status"] == ["ok"] * steps
    assert abs(result["values"]["x"][-1] - 3.5) < 1e-9, result["values"]["x"][-1]
