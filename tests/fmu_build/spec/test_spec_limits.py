"""Limits of the spec layer: messages name the field and the limit (docs/spec_reference.md)."""
import pytest

from tests.support.helpers import lag_spec as _spec
from tests.support.helpers import spec_problems as _problems
from fmu_build import SpecError, build_fmu, load_spec, parse_spec
from fmu_build.spec._limits import MAX_DERIVATIVE_SIZE, MAX_LAM, derivative_problems


@pytest.mark.parametrize("text, char", [("ℯ**t", "U+212F"), ("sin(t) + ｔ", "U+FF54"), ("2*t # é", "U+00E9")])
def test_non_ascii_character_is_named_with_its_code_point(text, char):
    problems = _problems(_spec(equations={"A": [["tau"]], "B": [[1]], "f": [text]}))
    assert len(problems) == 1 and problems[0].startswith("equations.f[0]:") and char in problems[0], problems


def test_degree_limit_counts_functions_as_their_argument():
    problems = _problems(_spec(equations={"A": [["tau"]], "B": [[1]], "f": ["sin(t**600)**2"]}))
    assert problems[0].startswith("equations.f[0]:") and "degree 1200" in problems[0], problems
    assert parse_spec(_spec(equations={"A": [["tau"]], "B": [[1]], "f": ["t**500*t**500"]})).f[0].as_base_exp()[1] == 1000


def test_default_description_with_a_tab_is_not_blamed():
    spec = parse_spec(_spec(outputs={"o": "x +\t1"}))
    assert spec.outputs[0]["description"] == "output o = x + 1"


def test_lam_bound_in_spec_and_in_build_override(tmp_path):
    assert parse_spec(_spec(completion={"lam": MAX_LAM})).lam == MAX_LAM
    problems = _problems(_spec(completion={"lam": 1e13}))
    assert len(problems) == 1 and problems[0].startswith("completion.lam: must be at most 1e+12"), problems
    with pytest.raises(ValueError, match="lam: must be at most"):
        build_fmu(_spec(), tmp_path, lam=1e13)
    assert not list(tmp_path.iterdir())


def test_step_lost_in_rounding_names_the_step_and_the_smallest_usable_one():
    problems = _problems(_spec(experiment={"start": 1e20, "stop": 2e20, "step": 0.01}))
    assert len(problems) == 1 and problems[0].startswith("experiment.step:") and "2e+08" in problems[0], problems
    # 1e-12 relative is accepted: the step still changes the time
    spec = parse_spec(_spec(experiment={"start": 1e6, "stop": 2e6, "step": 2e-6}))
    assert spec.experiment["stop"] + spec.experiment["step"] > spec.experiment["stop"]


def test_derivative_size_names_the_entry_and_the_order():
    index2 = {"model": {"name": "Swell"}, "states": {"x": {}, "y": {}},
              "equations": {"A": [[1, 0], [0, 0]], "B": [[0, -1], [1, 0]], "f": [0, "sin(sin(sin(sin(sin(sin(sin(sin(t))))))))"]}}
    spec = parse_spec(index2)
    assert derivative_problems(spec, 2) == []  # 425 nodes at order 2
    problems = derivative_problems(spec, 22)
    assert len(problems) == 1 and problems[0].startswith("equations.f[1]: its derivative of order 3 has more than "
                                                         f"{MAX_DERIVATIVE_SIZE}"), problems


def test_non_utf8_position_is_line_and_column(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_bytes(b'[model]\nname = "B\xff"\n')
    with pytest.raises(SpecError) as info:
        load_spec(path)
    assert "byte position 17 (line 2, column 10)" in info.value.problems[0], info.value.problems
