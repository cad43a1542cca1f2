"""Property-based fuzzing of the spec parser (hypothesis).

Random expressions built from allowed nodes (numbers of any size, declared and undeclared names,
``+ - * / **``, unary signs, calls of the whitelisted functions with any number of arguments)
and forbidden ones (attributes, subscripts, lambdas, comprehensions, strings, ``eval``, calls of
other names, keywords, walrus, ...), and random specs (known and unknown keys, values of every
TOML type, texts with control characters) must all end in a parsed spec or a `SpecError`:

- no other exception escapes `parse_spec`;
- no code in a spec is ever executed: every forbidden construct calls a sentinel that records
  the call, and the record must stay empty;
- no case hangs: each runs under a SIGALRM deadline of `HANG_GUARD` seconds (a guard against
  hangs, far above the time a case takes, which is well under a second).

The default run draws 100 examples per test. For a longer search set the environment variable
``LSC_FUZZ_EXAMPLES``, e.g. ``LSC_FUZZ_EXAMPLES=20000 python -m pytest tests/fmu_build/spec/test_spec_fuzz.py``.
"""
import builtins
import math
import os
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.support.helpers import deadline
from fmu_build import SpecError, parse_spec
from fmu_build.spec._expressions import FUNCTIONS

EXAMPLES = int(os.environ.get("LSC_FUZZ_EXAMPLES", "100"))
HANG_GUARD = 10.0  # seconds: a hang guard, not a speed test
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                    print_blob=True)

CALLS = []  # the sentinel's record: must stay empty
SENTINEL = "_spec_fuzz_sentinel"


@pytest.fixture(autouse=True, scope="module")
def sentinel():
    """A builtin any executed spec code would reach: calling it records the call."""
    setattr(builtins, SENTINEL, lambda *args: CALLS.append(args) or 0)
    yield
    delattr(builtins, SENTINEL)


# --- expressions -------------------------------------------------------------------------------
NAMES = ["t", "m", "p", "x", "pi", "e", "q", "inf", "nan", "__builtins__", SENTINEL, "os", "self"]
numbers = st.one_of(
    st.integers(min_value=-10**6, max_value=10**6).map(str),
    st.integers(min_value=0, max_value=10**400).map(str),
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.sampled_from(["1e400", "1e-400", "0", "0.0", "9", "10", "1000000000", "0x10", "1_000", "1j"]),
)
atoms = st.one_of(numbers, st.sampled_from(NAMES))


def _allowed(children):
    return st.one_of(
        st.tuples(children, st.sampled_from(["+", "-", "*", "/", "**"]), children).map(lambda a: f"({a[0]} {a[1]} {a[2]})"),
        st.tuples(st.sampled_from(["-", "+"]), children).map(lambda a: f"{a[0]}{a[1]}"),
        st.tuples(st.sampled_from(sorted(FUNCTIONS)), st.lists(children, max_size=3)).map(lambda a: f"{a[0]}({', '.join(a[1])})"),
    )


def _forbidden(children):
    s = SENTINEL
    return st.one_of(
        st.sampled_from([
            f"{s}()", f"__import__('builtins').{s}()", f"eval('{s}()')", f"exec('{s}()')", f"(lambda: {s}())()",
            f"[{s}() for _ in [1]][0]", f"{{{s}()}}", f"({s}(), 1)[1]", f"(y := {s}())", f"{s}() if 1 else 0",
            f"t.__class__.__mro__[1].__subclasses__()", f"{s}.__call__()", f"sin(t).func", "'text'", "b'bytes'",
            f"f'{{{s}()}}'", "...", "None", "True", "1 < 2", "t and m", "not t", "~1", "1 // 2", "1 % 2", "1 @ 2",
            "1 << 2", "sin(x=t)", "sin(*[t])", "atan2(**{})", "[t]", "{1: 2}", "t[0]", "t.real", "await t",
            "yield t", "(t for t in t)", "", "   ", "(", "1 +", "1 2", "sin", "x\x00", "\u00e9", "t\n+1",
        ]),
        st.tuples(children, st.sampled_from([".real", "[0]", "()", ".__class__"])).map(lambda a: f"({a[0]}){a[1]}"),
        st.tuples(st.sampled_from(["open", "print", SENTINEL, "getattr", "Symbol", "sympify", "exp.func"]),
                  st.lists(children, max_size=2)).map(lambda a: f"{a[0]}({', '.join(a[1])})"),
    )


expressions = st.recursive(atoms, lambda children: st.one_of(_allowed(children), _forbidden(children)), max_leaves=15)
allowed_expressions = st.recursive(atoms, _allowed, max_leaves=15)


def _spec(f_entry):
    return {"model": {"name": "Fuzz"}, "states": {"x": {"start": 1.0}, "v": {}},
            "parameters": {"m": {"value": 2.0}}, "inputs": {"p": {}},
            "equations": {"A": [[1, 0], [0, "m"]], "B": [[0, -1], [0, 0]], "f": [0, f_entry]}}


def _parse(data):
    """parse_spec under the hang guard: a ModelSpec, or None for a SpecError; anything else fails."""
    start = time.perf_counter()
    with deadline(HANG_GUARD, "a spec case still ran"):
        try:
            spec = parse_spec(data)
        except SpecError as exc:
            assert exc.problems and all(isinstance(p, str) and p for p in exc.problems)
            spec = None
    assert CALLS == [], f"spec code was executed: {CALLS}"
    return spec, time.perf_counter() - start


@SETTINGS
@given(expressions)
def test_random_expressions_parse_or_raise_spec_error(text):
    _parse(_spec(text))


@SETTINGS
@given(allowed_expressions)
def test_accepted_expressions_have_finite_real_values_at_the_start(text):
    # what the parser accepts, the build can evaluate: A, B, f are finite and real at the start time
    spec, _ = _parse(_spec(text))
    if spec is not None:
        from fmu_build.spec._expressions import evaluate

        values = {spec.t: spec.experiment["start"], spec.symbols["m"]: 2.0, spec.input_symbols["p"]: 0.0}
        assert math.isfinite(evaluate(spec.f[1], values))


# --- whole specs -------------------------------------------------------------------------------
KEYS = ["model", "states", "parameters", "inputs", "equations", "outputs", "completion", "experiment", "name",
        "description", "start", "unit", "value", "tunable", "expr", "A", "B", "f", "method", "lam", "k", "stop",
        "step", "lamda", "stpo", "tunabel", "x", "v", "m", "p", "p__1", "_lsc_x", "x_0", "os", "MODEL", "lambda",
        "", " ", "é", "a.b", "1x", "class"]
keys = st.one_of(st.sampled_from(KEYS), st.text(max_size=12))
texts = st.one_of(st.text(max_size=30), st.sampled_from(["\x00", "a\x07b", "\ud7ff", "\ufffe", "m/s", "N.s/m"]))
scalars = st.one_of(st.none(), st.booleans(), st.integers(min_value=-2**70, max_value=10**400),
                    st.floats(), texts, expressions)
values = st.recursive(scalars, lambda children: st.one_of(st.lists(children, max_size=4),
                                                          st.dictionaries(keys, children, max_size=4)), max_leaves=12)


@st.composite
def mutated_specs(draw):
    """The valid base spec with a few random keys set to random values, at any depth."""
    data = _spec(draw(st.one_of(allowed_expressions, st.just("sin(t)"))))
    data["outputs"] = {"energy": {"expr": "m*v**2/2", "unit": "J"}}
    data["completion"] = {"method": "alternative", "lam": 2.0}
    data["experiment"] = {"start": 0.0, "stop": 1.0, "step": 0.1}
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        table = data
        for _ in range(draw(st.integers(min_value=0, max_value=2))):
            children = [k for k, v in table.items() if isinstance(v, dict)]
            if not children:
                break
            table = table[draw(st.sampled_from(sorted(children)))]
        key = draw(st.one_of(st.sampled_from(sorted(table) or ["model"]), keys))
        table[key] = draw(values)
    return data


@SETTINGS
@given(mutated_specs())
def test_random_specs_parse_or_raise_spec_error(data):
    _parse(data)


@SETTINGS
@given(values)
def test_any_value_as_the_whole_spec(data):
    _parse(data)
