"""The problems and ``(method, lam)`` pairs the library tests run over."""
import numpy as np

from lsc import COMPLETIONS, gallery

# (method, lam) pairs that every completion test runs over.
METHOD_LAMS = [("standard", None), ("stabilized", 2.0), ("alternative", 2.0)]


def method_lams():
    assert set(m for m, _ in METHOD_LAMS) == set(COMPLETIONS)
    return METHOD_LAMS


def assert_same_spectrum(found, expected, rtol=1e-8, atol=1e-8):
    """Multisets equal: each expected value matched to its nearest found one."""
    found = list(np.asarray(found, dtype=complex))
    expected = np.asarray(expected, dtype=complex)
    assert len(found) == len(expected), (found, expected)
    for mu in expected:
        j = int(np.argmin([abs(f - mu) for f in found]))
        assert abs(found[j] - mu) <= atol + rtol * abs(mu), (found, expected)
        found.pop(j)


CONSTANT_PROBLEMS = {
    **{f"chain{i}": (lambda i=i: gallery.nilpotent_chain(i)) for i in range(1, 7)},
    **{f"chain{i}-mixed": (lambda i=i: gallery.nilpotent_chain(i, seed=i)) for i in range(1, 7)},
    "pencil-3-2": lambda: gallery.random_pencil(n=12, blocks=(3, 2), seed=1),
    "pencil-4-1-1": lambda: gallery.random_pencil(n=10, blocks=(4, 1, 1), seed=2),
    "mechanical": gallery.mechanical,
    "prescribed_path": gallery.prescribed_path,
}
