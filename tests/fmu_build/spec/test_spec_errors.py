"""The spec layer's table of bad (and good) input: (spec fragment, expected outcome, message fragment).

Each fragment is TOML merged into a valid base spec (tables merge key by key, anything else is
replaced), so every row shows exactly what a user would write. A refusal must be a `SpecError`
whose message holds the fragment; an accepted spec must parse. Every row runs under a deadline
(SIGALRM) so a hang fails the test instead of stalling the suite.
"""
import tomllib

import pytest

from tests.support.helpers import deadline
from fmu_build import SpecError, build_fmu, parse_spec

BASE = """
[model]
name = "Base"
description = "a valid spec the rows below modify"

[states]
x = { unit = "m", start = 1.0 }
v = { unit = "m/s" }

[parameters]
m = { value = 2.0, unit = "kg", tunable = true }

[inputs]
p = { unit = "N" }

[equations]
A = [[1, 0], [0, "m"]]
B = [[0, -1], [0, 0]]
f = [0, "p + sin(t)"]

[completion]
method = "alternative"
lam = 2.0

[experiment]
start = 0.0
stop = 1.0
step = 0.1
"""

DEEP_MINUS = "-" * 100_000 + "1"
NESTED_MINUS = "-(" * 150 + "1" + ")" * 150  # short but deeper than allowed

OK, REFUSED = "ok", SpecError

ROWS = [
    # generated names never collide with spec names
    ('[parameters]\np__1 = 3.5', REFUSED, "parameters.p__1: 'p__1' is reserved: names containing '__'"),
    ('[parameters]\n_lsc_params = 1.0', REFUSED, "parameters._lsc_params: '_lsc_params' is reserved"),
    ('[inputs]\nu__0 = {}', REFUSED, "inputs.u__0: 'u__0' is reserved"),
    ('[states]\nw__1 = {}', REFUSED, "states.w__1: 'w__1' is reserved"),
    ('[parameters]\nx_0 = 1.0', REFUSED, "parameters.x_0: 'x_0' clashes with the start value of the state 'x'"),
    ('[outputs]\nv_0 = "v"', REFUSED, "outputs.v_0: 'v_0' clashes with the start value of the state 'v'"),
    ('[inputs]\nm = {}', REFUSED, "inputs.m: 'm' clashes with a parameter of that name"),
    ('[parameters]\nlambda_ = 1.0\nout = 2.0\norder = 3.0\nnp = 4.0\nmath = 5.0\nfloat = 6.0', OK, None),
    # unknown and misspelled keys, each with a suggestion
    ('[completion]\nlamda = 5.0', REFUSED, "completion.lamda: unknown key 'lamda' in [completion]; did you mean 'lam'?"),
    ('[experiment]\nstpo = 5', REFUSED, "experiment.stpo: unknown key 'stpo' in [experiment]; did you mean 'stop'?"),
    ('[parameters]\nc = { value = 1.0, tunabel = true }', REFUSED,
     "parameters.c.tunabel: unknown key 'tunabel' in [parameters.c]; did you mean 'tunable'?"),
    ('[states]\ny = { strat = 1.0 }', REFUSED, "states.y.strat: unknown key 'strat' in [states.y]; did you mean 'start'?"),
    ('[inputs]\nq = { unti = "m" }', REFUSED, "inputs.q.unti: unknown key 'unti' in [inputs.q]; did you mean 'unit'?"),
    ('[outputs]\ne = { exp = "x" }', REFUSED, "outputs.e.exp: unknown key 'exp' in [outputs.e]; did you mean 'expr'?"),
    ('[model]\nnmae = "X"', REFUSED, "model.nmae: unknown key 'nmae' in [model]; did you mean 'name'?"),
    ('[equations]\nF = [0, 0]', REFUSED, "equations.F: unknown key 'F' in [equations]; did you mean 'f'?"),
    ('[experimnet]\nstop = 2.0', REFUSED, "experimnet: unknown table [experimnet]; did you mean [experiment]?"),
    ('[completion]\nzzz = 1', REFUSED, "completion.zzz: unknown key 'zzz' in [completion] (known: method, lam, k)"),
    # sizes that would hang the build
    ('[equations]\nf = [0, "9**9**9"]', REFUSED, "equations.f[1]: exponent 387420489 is too large (at most 1000"),
    ('[equations]\nf = [0, "10**1000000000"]', REFUSED, "equations.f[1]: exponent 1000000000 is too large"),
    ('[equations]\nB = [[0, "(10**300)*(10**300)"], [0, 0]]', REFUSED, "equations.B[0][1]: a number in the expression is out of range"),
    ('[equations]\nf = [0, "2**1000 * 2**1000"]', REFUSED, "equations.f[1]: a number in the expression is out of range"),
    ('[equations]\nf = [0, "10**-400"]', REFUSED, "equations.f[1]: 10**-400 is out of range"),
    ('[equations]\nf = [0, "t**2000"]', REFUSED, "equations.f[1]: exponent 2000 is too large"),
    (f'[equations]\nf = [0, "{"9" * 4500}"]', REFUSED, "equations.f[1]:"),
    ('[equations]\nf = [0, "2**0.5 * t**3 + 1e300"]', OK, None),
    # texts and types that would break the model description
    ('[model]\ndescription = "bad\\u0000text"', REFUSED, "model.description: control character '\\x00' at position 3"),
    ('[states]\nx = { unit = 5 }', REFUSED, "states.x.unit: expected text, got 5"),
    ('[states]\nx = { unit = "m\\u0007" }', REFUSED, "states.x.unit: control character '\\x07'"),
    ('[parameters]\nm = { value = 2.0, description = ["a"] }', REFUSED, "parameters.m.description: expected text, got ['a']"),
    ('[outputs]\ne = { expr = "x", unit = true }', REFUSED, "outputs.e.unit: expected text, got True"),
    ('[parameters]\nm = { value = 2.0, tunable = "yes" }', REFUSED, "parameters.m.tunable: expected true or false, got 'yes'"),
    ('[states]\ny = 5', REFUSED, "states.y: expected a table { start = ..., unit = ..., description = ... }, got 5"),
    ('model = "M"', REFUSED, "model: expected a table, got 'M'"),
    ('completion = 3', REFUSED, "completion: expected a table, got 3"),
    ('[model]\nname = 5', REFUSED, "model.name: expected a name (text), got 5"),
    ('[model]\ndescription = "Ünïcode, tabs\\tand newlines\\n are not it: only control characters"', REFUSED,
     "model.description: control character '\\t'"),
    ('[model]\ndescription = "Ünïcode and “quotes” <&> are fine"', OK, None),
    # unclear errors that must name the field, the expected and the found
    ('[equations]\nf = [0, "atan2(t)"]', REFUSED, "equations.f[1]: atan2() takes 2 arguments, got 1"),
    ('[equations]\nf = [0, "sin(t, t)"]', REFUSED, "equations.f[1]: sin() takes 1 argument, got 2"),
    ('[equations]\nf = [0, "log(-1)"]', REFUSED, "equations.f[1]: 'log(-1)' is not real"),
    ('[equations]\nf = [0, "(-8)**(1/3)"]', REFUSED, "equations.f[1]: (-8)**(1/3) is not real"),
    ('[equations]\nB = [[0, -1], ["m/0", 0]]', REFUSED, "equations.B[1][0]: 'm/0' is not finite (a division by zero?)"),
    ('[parameters]\nm = inf', REFUSED, "parameters.m.value: expected a finite number, got inf"),
    ('[parameters]\nm = { value = -inf }', REFUSED, "parameters.m.value: expected a finite number, got -inf"),
    ('[states]\nx = { start = nan }', REFUSED, "states.x.start: expected a finite number, got nan"),
    ('[inputs]\np = { start = inf }', REFUSED, "inputs.p.start: expected a finite number, got inf"),
    ('[completion]\nlam = nan', REFUSED, "completion.lam: expected a finite number, got nan"),
    ('[experiment]\nstop = inf', REFUSED, "experiment.stop: expected a finite number, got inf"),
    ('[equations]\nf = [0, "1e400"]', REFUSED, "equations.f[1]:"),
    ('[completion]\nk = 1000000', REFUSED, "completion.k: must be an integer from 0 to 20; got 1000000"),
    ('[parameters]\nc = {}', REFUSED, "parameters.c.value: missing (expected a number)"),
    (f'[equations]\nf = [0, "{DEEP_MINUS}"]', REFUSED, "equations.f[1]: expression of 100001 characters is too long"),
    (f'[equations]\nf = [0, "{NESTED_MINUS}"]', REFUSED, "equations.f[1]: expression nested"),
    (f'[model]\nname = "{"M" * 300}"', REFUSED, "model.name: a name of 300 characters is too long (at most 64)"),
    (f'[parameters]\n{"q" * 101} = 1.0', REFUSED, "a name of 101 characters is too long (at most 100)"),
    # the modules inside an FMU are named by a hash of its content: a model may be named like any module
    *[(f'[model]\nname = "{module}"', OK, None)
      for module in ("MODEL", "Fmi2Slave", "pythonfmu", "json", "os", "numpy", "ctypes", "fmpy", "lsc", "sys", "math")],
    ('[model]\nname = "__init__"', REFUSED, "model.name: '__init__' is reserved"),
    ('[equations]\nf = [0, "1/t"]', REFUSED,
     "equations.f[1]: '1/t' has no finite real value at t = 0.0 (experiment.start), with the parameters' values"),
    ('[equations]\nf = [0, "log(t - 1)"]', REFUSED, "equations.f[1]: 'log(t - 1)' has no finite real value at t = 0.0"),
    ('[equations]\nA = [[1, 0], [0, "sqrt(m - 3)"]]', REFUSED, "equations.A[1][1]: 'sqrt(m - 3)' has no finite real value"),
    ('[equations]\nf = [0, "1/p"]', REFUSED, "equations.f[1]: '1/p' has no finite real value at t = 0.0"),
    ('[equations]\nf = [0, "1/t"]\n[experiment]\nstart = 0.5', OK, None),
]


def _merge(base, fragment):
    for key, value in fragment.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            _merge(base[key], value)
        else:
            base[key] = value
    return base


def test_base_spec_is_valid():
    spec = parse_spec(tomllib.loads(BASE))
    assert spec.n == 2 and [p["name"] for p in spec.parameters] == ["m"] and spec.lam == 2.0


@pytest.mark.parametrize("fragment, expected, message", ROWS, ids=[f"{i}-{row[0][:40]}" for i, row in enumerate(ROWS)])
def test_spec_table(fragment, expected, message):
    data = _merge(tomllib.loads(BASE), tomllib.loads(fragment))
    with deadline(20):
        if expected is OK:
            parse_spec(data)
            return
        with pytest.raises(SpecError) as info:
            parse_spec(data)
    assert message in str(info.value), str(info.value)


def test_every_problem_is_reported_at_once():
    fragment = '[completion]\nlamda = 5.0\n[states]\nx = { unit = 5, start = nan }\n[equations]\nf = [0, "atan2(t)"]'
    with pytest.raises(SpecError) as info:
        parse_spec(_merge(tomllib.loads(BASE), tomllib.loads(fragment)))
    assert len(info.value.problems) == 4, info.value.problems


@pytest.mark.parametrize("name, message", [
    ("1x", "model_name: '1x' is not a valid identifier"),
    ("M" * 300, "model_name: a name of 300 characters is too long"),
    ("_lsc_model", "model_name: '_lsc_model' is reserved"),
])
def test_build_fmu_model_name_override_is_checked(name, message, tmp_path):
    import sys

    modules = set(sys.modules)
    with pytest.raises(SpecError, match=message):
        build_fmu(tomllib.loads(BASE), tmp_path, model_name=name)
    assert list(tmp_path.iterdir()) == [] and set(sys.modules) >= modules


SQRT_SPEC = """
[model]
name = "RootForcing"
[states]
x = {}
y = {}
[equations]
A = [[0, 1], [0, 0]]
B = [[1, 0], [0, 1]]
f = [0, "sqrt(t)"]
"""


@pytest.mark.parametrize("start, refused", [(0.0, True), (0.25, False)])
def test_build_refuses_a_completion_not_finite_at_the_start(start, refused, tmp_path):
    # y = sqrt(t), x = -y': f is finite at t = 0, its derivative (which the completion uses) is not
    from fmu_build._model import _complete_at_start

    data = tomllib.loads(SQRT_SPEC)
    data["experiment"] = {"start": start, "stop": start + 1.0}
    spec = parse_spec(data)
    if refused:
        with pytest.raises(SpecError, match=r"equations\.f\[1\] \(derivative 1\): the completion has no finite value at t = 0.0"):
            build_fmu(spec, tmp_path)
        assert list(tmp_path.iterdir()) == []
    else:
        completion = _complete_at_start(spec.linear_dae(), spec, (start, start + 1.0))
        # on the solution x = -1/(2 sqrt t), y = sqrt t the completion gives its exact derivative
        exact = [-0.5 * start**-0.5, start**0.5]
        derivative = [0.25 * start**-1.5, 0.5 * start**-0.5]
        assert completion.rhs(start, exact) == pytest.approx(derivative, rel=1e-9)


def test_build_fmu_k_override_is_bounded(tmp_path):
    with pytest.raises(ValueError, match="`k` must be an integer from 0 to 20; found 1000000"):
        build_fmu(tomllib.loads(BASE), tmp_path, k=1_000_000)
    assert list(tmp_path.iterdir()) == []
