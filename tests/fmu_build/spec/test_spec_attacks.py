"""Hostile inputs to fmu_build's spec parser and build that are not handled as promised.

Every test asserts what SHOULD happen (docs/spec_reference.md, fmu_build/spec/_spec.py): a
clear SpecError naming the field, a bounded build, an FMU that works or is refused, and
no broken file left at the destination. They fail today.
"""
import json
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest

from tests.support.helpers import lag_spec as _spec
from tests.support.helpers import spec_problems as _problems
from fmu_build import SpecError, build_fmu, load_spec

from tests.support import ROOT


def _run(code, timeout):
    """Run `code` in a fresh Python with this checkout first on the path."""
    env_path = str(ROOT)
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env={"PYTHONPATH": env_path, "PATH": "/usr/bin:/bin",
                                                "HOME": str(Path.home())})


# Shows: _IDENT's `$` matches before a trailing newline, so the model name "Lag\n" passes
# parse_spec and the build then dies with a raw SyntaxError in the generated "Lag\n.py".
def test_model_name_with_trailing_newline_is_refused():
    problems = _problems(_spec(model={"name": "Lag\n"}))
    assert any(p.startswith("model.name:") for p in problems), problems


# Shows: a variable name with a trailing newline is accepted when a description is given;
# the FMU then has variables named "x " and "x _0" (XML turns the newline into a space).
@pytest.mark.parametrize("section, entry", [
    ("states", {"x\n": {"description": "d"}}),
    ("parameters", {"q\n": {"value": 1.0, "description": "d"}}),
    ("inputs", {"u\n": {"description": "d"}}),
    ("outputs", {"o\n": {"expr": "x", "description": "d"}}),
])
def test_variable_name_with_trailing_newline_is_refused(section, entry):
    spec = _spec()
    spec.setdefault(section, {}).update(entry)
    problems = _problems(spec)
    assert any(p.startswith(f"{section}.") and "identifier" in p for p in problems), problems


# Shows: without a description the name "x\n" is only caught through its default description,
# so the message blames states.x\n.description (a field the user never wrote), not the name.
def test_trailing_newline_name_error_names_the_name_not_the_description():
    problems = _problems(_spec(states={"x\n": {}}))
    assert not any(".description" in p for p in problems), problems
    assert any("identifier" in p for p in problems), problems


# Shows: Python's parser NFKC-normalizes identifiers, so the non-ASCII text "ｔａｕ*2" (fullwidth)
# silently means the parameter tau, although names must be ASCII identifiers.
def test_non_ascii_identifier_in_expression_is_refused():
    problems = _problems(_spec(equations={"A": [["tau"]], "B": [[1]], "f": ["ｔａｕ*2"]}))
    assert any(p.startswith("equations.f[0]:") for p in problems), problems


# Shows: the documented exponent limit ("t**2000 is refused") is bypassed by a product:
# "t**1000*t**1000" is accepted and becomes t**2000 (and 1600 factors (t+1) give (t+1)**1600).
@pytest.mark.parametrize("text", ["t**1000*t**1000", "*".join(["(t+1)"] * 1600)], ids=["t2000", "t_plus_1_x1600"])
def test_exponent_limit_is_not_bypassed_by_a_product(text):
    problems = _problems(_spec(equations={"A": [["tau"]], "B": [[1]], "f": [text]}))
    assert any(p.startswith("equations.f[0]:") for p in problems), problems


# Shows: "Limits keep every build short whatever the text" does not hold: an accepted f of 40
# factors (index 2), or 8 nested sin with k = 20, makes build_fmu run for minutes (> 60 s seen).
@pytest.mark.parametrize("f, k", [
    ("*".join(f"(t+{i})" for i in range(1, 41)), None),
    ("sin(sin(sin(sin(sin(sin(sin(sin(t))))))))", 20),
], ids=["product40", "nested_sin_k20"])
def test_build_of_an_accepted_spec_is_bounded(f, k, tmp_path):
    spec = {"model": {"name": "Swell"}, "states": {"x": {}, "y": {}},
            "equations": {"A": [[1, 0], [0, 0]], "B": [[0, -1], [1, 0]], "f": [0, f]}}
    if k is not None:
        spec["completion"] = {"k": k}
    code = f"""
        import json
        from fmu_build import build_fmu, SpecError
        try:
            build_fmu(json.loads({json.dumps(json.dumps(spec))}), {str(tmp_path)!r})
        except SpecError:
            pass
    """
    try:
        _run(code, timeout=30)
    except subprocess.TimeoutExpired:
        pytest.fail("build_fmu ran for more than 30 s on a spec parse_spec accepts")


# Shows: an experiment whose span overflows (stop - start = inf) or whose step is lost in the
# rounding of start (1e20 + 0.01 == 1e20) is accepted; the FMU's time can never advance.
@pytest.mark.parametrize("experiment", [
    {"start": -1e308, "stop": 1e308},
    {"start": 1e20, "stop": 2e20, "step": 0.01},
])
def test_experiment_whose_time_cannot_advance_is_refused(experiment):
    problems = _problems(_spec(experiment=experiment))
    assert any(p.startswith("experiment.") for p in problems), problems


# Shows: completion.lam = 1e308 is accepted and built, but the FMU overflows and cannot take a
# single step (fmpy's result ends at t = 0); the spec or the build should refuse it.
def test_extreme_lam_is_refused_or_the_fmu_steps(tmp_path):
    spec = {"model": {"name": "LamHuge"}, "states": {"x": {}, "y": {}},
            "equations": {"A": [[1, 0], [0, 0]], "B": [[0, -1], [1, 0]], "f": [0, "sin(t)"]},
            "completion": {"lam": 1e308}}
    try:
        fmu = build_fmu(spec, tmp_path)
    except SpecError as exc:
        assert any("lam" in p for p in exc.problems), exc.problems
        return
    result = _run(f"""
        import fmpy
        r = fmpy.simulate_fmu({str(fmu)!r}, stop_time=0.1)
        print(r["time"][-1])
    """, timeout=60)
    assert result.stdout.strip().splitlines()[-1] == "0.1", result.stdout + result.stderr


# Shows: two builds into the same folder at once leave a corrupt FMU (bad CRC, or a
# modelDescription from one spec with the code of the other) while both report success or one
# fails with a raw BadZipFile.
def test_two_concurrent_builds_into_one_folder_leave_a_valid_fmu(tmp_path):
    specs = [
        {"model": {"name": "Twin"}, "states": {"x": {"unit": "m"}}, "outputs": {"oa": "x"},
         "equations": {"A": [[1]], "B": [[1]], "f": ["sin(t)"]}},
        {"model": {"name": "Twin"}, "states": {"x": {"unit": "kg"}}, "outputs": {"ob": "2*x"},
         "equations": {"A": [[1]], "B": [[1]], "f": ["cos(t)"]}},
    ]
    code = """
        import json, sys
        from fmu_build import build_fmu
        build_fmu(json.loads(sys.argv[1]), sys.argv[2])
    """
    procs = [subprocess.Popen([sys.executable, "-c", textwrap.dedent(code), json.dumps(s), str(tmp_path)],
                              env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "HOME": str(Path.home())},
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for s in specs]
    outcomes = [p.communicate(timeout=120) for p in procs]
    errors = [err for (_, err), p in zip(outcomes, procs) if p.returncode != 0]
    assert not any("BadZipFile" in err for err in errors), errors
    with zipfile.ZipFile(tmp_path / "Twin.fmu") as zf:
        assert zf.testzip() is None
        md = zf.read("modelDescription.xml").decode()
        # the generated model module is named by a hash of the build's content
        src = zf.read(next(n for n in zf.namelist() if n.startswith("resources/") and n.endswith("_model.py"))).decode()
    # the description and the code come from the same spec
    for out, unit in (("oa", "m"), ("ob", "kg")):
        if f"'{out}'" in src:
            assert f'name="{out}"' in md and f'unit="{unit}"' in md, md


# Shows: a spec file that is not UTF-8 raises a bare UnicodeDecodeError (no file, no SpecError).
def test_non_utf8_spec_file_is_a_spec_error(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_bytes(b'[model]\nname = "B\xff"\n')
    with pytest.raises(SpecError) as info:
        load_spec(path)
    assert str(path) in str(info.value)


# Shows: a spec file with deeply nested arrays crashes load_spec (and `lsc-fmu build`, exit 1
# with a traceback) with RecursionError inside tomllib instead of a SpecError.
def test_deeply_nested_toml_is_a_spec_error(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text('[model]\nname = "Deep"\n[states]\nx = {}\n[equations]\nA = [[1]]\nB = [[1]]\n'
                    f"f = [{'[' * 5000}1{']' * 5000}]\n")
    with pytest.raises(SpecError):
        load_spec(path)


# Shows: the CLI prints a raw traceback and exits 1 on the nested TOML above (not "lsc-fmu: error:", exit 2).
def test_cli_reports_deeply_nested_toml_as_an_error(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text('[model]\nname = "Deep"\n[states]\nx = {}\n[equations]\nA = [[1]]\nB = [[1]]\n'
                    f"f = [{'[' * 5000}1{']' * 5000}]\n")
    result = subprocess.run([sys.executable, "-m", "fmu_build", "build", str(path), "-o", str(tmp_path)],
                            capture_output=True, text=True, timeout=60,
                            env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "HOME": str(Path.home())})
    assert result.returncode == 2, result.stderr[-500:]
    assert "Traceback" not in result.stderr
