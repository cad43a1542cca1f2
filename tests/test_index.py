import numpy as np
import pytest

from lsc import IndexDeterminationError, LinearDAE, differentiation_index, gallery


@pytest.mark.parametrize("index", range(1, 7))
def test_chain_index(index):
    assert differentiation_index(gallery.nilpotent_chain(index, seed=index).dae) == index


def test_ode_has_index_zero():
    assert differentiation_index(LinearDAE(np.eye(3) + np.eye(3, k=1), np.ones((3, 3)))) == 0


def test_index_is_the_longest_chain():
    p = gallery.random_pencil(n=15, blocks=(2, 4, 1), seed=5)
    assert differentiation_index(p.dae) == 4


def test_kmax_too_small_lists_ranks():
    p = gallery.nilpotent_chain(4)
    with pytest.raises(IndexDeterminationError) as info:
        differentiation_index(p.dae, kmax=2)
    msg = str(info.value)
    assert "no k in 0..2" in msg
    # one line per k tried, with its ranks
    for k in range(3):
        assert f"k={k}: rank J=" in msg


def test_singular_pencil_is_refused():
    # x1' + x2 = f1 and 0 = 0: det(sA + B) == 0 for all s.
    dae = LinearDAE([[1, 0], [0, 0]], [[0, 1], [0, 0]])
    with pytest.raises(IndexDeterminationError, match="singular"):
        differentiation_index(dae)


def test_singular_pencil_without_zero_rows_is_refused():
    # L_1 + L_1^T Kronecker blocks: no zero row, still singular.
    A = np.array([[1.0, 0, 0], [0, 0, 1], [0, 0, 0]])
    B = np.array([[0.0, 1, 0], [0, 0, 0], [0, 0, 1]])
    with pytest.raises(IndexDeterminationError, match="singular"):
        differentiation_index(LinearDAE(A, B))
