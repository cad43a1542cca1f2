"""Set-up work that is reused must give the decisions computing it afresh gives."""

import numpy as np
import pytest
import scipy.linalg

from lsc import gallery
from lsc._derivative_array import array_jets
from lsc._index import array_ranks, determine_index


@pytest.mark.parametrize("p", [gallery.nilpotent_chain(3, seed=0), gallery.random_pencil(n=12, blocks=(3, 2), seed=1),
                               gallery.nilpotent_chain(5, seed=2)], ids=lambda p: p.name)
def test_reused_singular_values_are_those_of_the_shifted_array(p):
    # constant coefficients: J[:, n:] with k differentiations is J with k - 1 below a zero block row
    n = p.dae.n
    for k in range(1, p.index + 2):
        J_prev = array_jets(p.dae, k - 1, 0.0).J[0]
        J = array_jets(p.dae, k, 0.0).J[0]
        np.testing.assert_array_equal(J[:n, n:], 0.0)
        np.testing.assert_array_equal(J[n:, n:], J_prev)
        s_w, s_prev = scipy.linalg.svdvals(J[:, n:]), scipy.linalg.svdvals(J_prev)
        np.testing.assert_allclose(s_w, s_prev, rtol=0, atol=1e-13 * s_prev[0])


@pytest.mark.parametrize("p", [gallery.nilpotent_chain(4, seed=0), gallery.random_pencil(n=12, blocks=(3, 2), seed=1)],
                         ids=lambda p: p.name)
def test_reuse_gives_the_same_ranks(p):
    for k in range(1, p.index + 2):
        fresh = array_ranks(p.dae, k, 0.0, None)
        reused = array_ranks(p.dae, k, 0.0, None, previous=array_ranks(p.dae, k - 1, 0.0, None))
        assert str(fresh) == str(reused)


def test_index_determination_takes_fewer_svds(monkeypatch):
    calls = []
    real = scipy.linalg.svdvals
    monkeypatch.setattr(scipy.linalg, "svdvals", lambda M: calls.append(M.shape) or real(M))
    p = gallery.nilpotent_chain(3, seed=0)
    k, _ = determine_index(p.dae, 0.0, 10, None)
    assert k == 3
    assert len(calls) == 10  # J and [J, F] for k = 0..4, J[:, n:] reused (14 without the reuse)
