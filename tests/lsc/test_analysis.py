"""Spectral statements of thesis chapters 2-4, on the gallery and on random pencils."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lsc import complete, eigenanalysis, gallery

from tests.support.problems import assert_same_spectrum


def decidable(p, method, lam):
    """Whether the Jordan structure must be decided: the stabilized added
    part is non-normal like lam^(size-1), which limits what rounding allows."""
    return method != "stabilized" or max(lam, 1 / lam) ** (p.index - 1) <= 1e3


def check_spectrum(p, method, lam, rtol_lam=1e-7):
    c = complete(p.dae, method, lam=lam)
    e = eigenanalysis(c)
    if decidable(p, method, lam):
        assert e.jordan_blocks is not None, e.decision_gap
    # The DAE's own dynamics are kept (finite eigenvalues of the pencil) ...
    assert_same_spectrum(e.pencil, p.finite_eigenvalues, rtol=1e-8, atol=1e-9)
    assert_same_spectrum(e.kept, p.finite_eigenvalues, rtol=1e-7, atol=1e-8)
    assert e.added.shape == (sum(p.jordan_blocks),)
    if method == "standard":
        # ... and the added ones are 0, in Jordan blocks as long as the chains (Lemma 1).
        assert abs(e.added_value) <= 1e-10 * max(1.0, np.linalg.norm(e.H, 2))
        assert e.jordan_blocks == p.jordan_blocks
    elif method == "stabilized":
        # -lam, still in Jordan blocks (chapter 3, ERRATA item 5).
        assert e.added_value == pytest.approx(-lam, rel=rtol_lam)
        assert e.jordan_blocks in (None, p.jordan_blocks)
    else:
        # -lam with no Jordan blocks: G + lam I vanishes on the added subspace (chapter 4).
        assert e.added_value == pytest.approx(-lam, rel=1e-10)
        assert e.jordan_blocks == (1,) * sum(p.jordan_blocks)
        np.testing.assert_allclose(e.H, -lam * np.eye(len(e.added)), atol=1e-9 * lam)
    return e


@pytest.mark.parametrize("method, lam", [("standard", None), ("stabilized", 0.5), ("stabilized", 20.0), ("alternative", 0.5), ("alternative", 20.0)])
def test_gallery_spectra(problem, method, lam):
    check_spectrum(problem, method, lam)


def test_stabilized_nilpotent_part_is_exactly_nilpotent():
    # (H + lam I)^size == 0 on the added subspace, tested structurally.
    p = gallery.nilpotent_chain(4, seed=2)
    e = eigenanalysis(complete(p.dae, "stabilized", lam=3.0))
    M = e.H + 3.0 * np.eye(4)
    scale = np.linalg.norm(M, 2)
    assert np.linalg.norm(np.linalg.matrix_power(M, 4), 2) <= 1e-10 * scale**4
    assert np.linalg.norm(np.linalg.matrix_power(M, 3), 2) >= 1e-3 * scale**3  # one block of size 4
    # eigvals scatters a defective eigenvalue by about eps^(1/4): do not test that way.
    scatter = np.abs(np.linalg.eigvals(e.H) + 3.0).max()
    assert scatter > 1e-8


@st.composite
def pencils(draw):
    index = draw(st.integers(1, 4))
    rest = draw(st.lists(st.integers(1, index), min_size=0, max_size=2))
    blocks = tuple([index] + rest)
    a = sum(blocks)
    n = draw(st.integers(a, 12))
    spectrum = draw(st.lists(st.floats(-3.0, 1.0).filter(lambda v: abs(v) > 0.05), min_size=n - a, max_size=n - a))
    seed = draw(st.integers(0, 2**31))
    lam = draw(st.floats(0.1, 100.0))
    return gallery.random_pencil(n=n, blocks=blocks, spectrum=spectrum, seed=seed, cond=5.0), lam


@settings(max_examples=int(__import__("os").environ.get("LSC_HYPOTHESIS_EXAMPLES", 40)), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pencils())
def test_property_standard(case):
    p, _ = case
    check_spectrum(p, "standard", None)


@settings(max_examples=int(__import__("os").environ.get("LSC_HYPOTHESIS_EXAMPLES", 40)), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pencils())
def test_property_stabilized(case):
    p, lam = case
    check_spectrum(p, "stabilized", lam, rtol_lam=1e-5)


@settings(max_examples=int(__import__("os").environ.get("LSC_HYPOTHESIS_EXAMPLES", 40)), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pencils())
def test_property_alternative(case):
    p, lam = case
    check_spectrum(p, "alternative", lam)
