"""One set of rules for FMI values and for a step over a horizon: the master and the studies agree.

The co-simulation master (start values, SSP parameter bindings) and the
studies (grid values) read a value for an FMI variable by the rules of
`fmu_build._values.fmi_value`, and count fixed steps over a horizon by
`fmu_build._values.steps_over`: whatever one accepts the other accepts, with
the same value, and whatever one refuses the other refuses.
"""
import numpy as np
import pytest

from fmu_build.cosim._exchange import convert
from fmu_build.cosim._master import _check_horizon
from fmu_build.study._runs import fmi_value, steps_over

VALUES = [
    ("false", "Boolean"), (" TRUE ", "Boolean"), (0.0, "Boolean"), (1.0, "Boolean"), (np.bool_(True), "Boolean"),
    (0.5, "Boolean"), (2, "Boolean"), ("yes", "Boolean"), (None, "Boolean"),
    ("3", "Integer"), ("3.0", "Integer"), (4.0, "Integer"), (np.int64(-7), "Integer"), (2.5, "Integer"),
    (True, "Integer"), (-2 ** 31, "Integer"), (2 ** 31, "Integer"), (str(2 ** 32 + 3), "Integer"),
    (float("inf"), "Integer"), ("x", "Integer"),
    ("2.5", "Real"), (3, "Real"), (np.float32(0.5), "Real"), (True, "Real"), ("abc", "Real"), (None, "Real"),
    ("s", "String"), ("a\0b", "String"), ("\ud800", "String"), (3, "String"),
]


def _outcome(read):
    try:
        value = read()
    except (TypeError, ValueError):
        return "refused"
    return type(value).__name__, value


@pytest.mark.parametrize("value, kind", VALUES)
def test_the_master_and_the_studies_read_a_value_alike(value, kind):
    master = _outcome(lambda: convert(value, kind, "v"))
    study = _outcome(lambda: fmi_value("v", value, kind))
    assert master == study


@pytest.mark.parametrize("t0, t1, h", [(0.0, 1.0, 0.3), (1e6, 1e6 + 1.0, 0.1001), (0.0, 1.0, 0.0)])
def test_a_step_that_does_not_divide_the_horizon_is_refused_by_both(t0, t1, h):
    # at t0 = 1e6 the study's tolerance (1e-9 of |t1|) took 0.1001 for a divisor of 1: its run ended 1e-3 early
    with pytest.raises(ValueError, match="does not divide the horizon"):
        steps_over(t0, t1, h)
    if h > 0:
        with pytest.raises(ValueError, match="does not divide the horizon"):
            _check_horizon(t0, t1, h)


@pytest.mark.parametrize("t0, t1, h, n", [(0.0, 1.0, 0.1, 10), (1e6, 1e6 + 1.0, 0.125, 8), (-3.0, 7.0, 0.01, 1000)])
def test_a_step_that_divides_the_horizon_is_taken_by_both(t0, t1, h, n):
    assert steps_over(t0, t1, h) == n
    _check_horizon(t0, t1, h)
