"""The checks on a callable coefficient's values cost no Python work per entry.

A time-varying completion evaluates its coefficients' jets at every time; a
check that visits each entry as a Python object (to find complex numbers)
made that the largest cost of an evaluation at n = 200. A real ndarray cannot
hold complex values, so only lists and object arrays are scanned: measured
here by the memory the check allocates (a per-entry scan boxes every entry).
"""
import tracemalloc

import numpy as np
import pytest

from lsc import LinearDAE
from lsc import JetCallable


def test_a_real_jet_is_checked_without_boxing_its_entries():
    n, order = 120, 3
    value = np.random.default_rng(0).standard_normal((order + 1, n, n))
    dae = LinearDAE(JetCallable(lambda t, o: value[: o + 1]), np.eye(n))
    dae.A.jet(0.1, order)  # first call: any one-off set-up
    tracemalloc.start()
    try:
        out = dae.A.jet(0.2, order)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    np.testing.assert_array_equal(out, value)
    assert peak < value.nbytes / 2, (peak, value.nbytes)  # boxing each float costs > 3 x nbytes


@pytest.mark.parametrize("bad", [[[1j]], np.array([[1j]], dtype=object)], ids=["list", "object array"])
def test_complex_values_are_still_refused(bad):
    dae = LinearDAE(JetCallable(lambda t, o: np.array([bad] * (o + 1), dtype=object)), [[1.0]])
    with pytest.raises(TypeError, match="complex"):
        dae.A.jet(0.0, 1)
