"""Reading descriptor systems ``E x' = A x + B u``, ``y = C x`` from Matrix Market or MATLAB files."""

import os

import numpy as np
import scipy.io
import scipy.sparse as sp

from .._exceptions import DimensionError
from ._sparse_base import Descriptor

_NAMES = ("E", "A", "B", "C")
_MM_SUFFIXES = ("{p}.{X}", "{p}.{X}.mtx", "{p}_{X}.mtx", "{p}{X}.mtx")


def _matrix(name, value, source):
    if sp.issparse(value):
        M = sp.csr_matrix(value)
    else:
        arr = np.asarray(value)
        if arr.dtype == object or arr.dtype.kind not in "biufc":
            raise TypeError(f"`{name}` in {source} is not a numeric matrix; found {arr.dtype}.")
        M = sp.csr_matrix(np.atleast_2d(arr))
    if np.iscomplexobj(M.data):
        raise TypeError(f"`{name}` in {source} is complex; lsc needs real matrices.")
    if not np.all(np.isfinite(M.data)):
        raise ValueError(f"`{name}` in {source} has NaN or inf entries.")
    return M.astype(float)


def _from_mat(path):
    data = scipy.io.loadmat(path)
    found = {}
    for key, value in data.items():
        if key.startswith("__"):
            continue
        up = key.upper()
        if up in _NAMES and up not in found:
            found[up] = value
    return found


def _from_matrix_market(prefix):
    found = {}
    for X in _NAMES:
        for pattern in _MM_SUFFIXES:
            path = pattern.format(p=prefix, X=X)
            if os.path.isfile(path):
                found[X] = scipy.io.mmread(path)
                break
    return found


def read_descriptor(source):
    """Read ``E, A, B, C`` of a descriptor system ``E x' = A x + B u``, ``y = C x``.

    The benchmark collections (the MOR Wiki, SLICOT, M-M.E.S.S.) ship large
    linear DAEs in this convention, which is also Kunkel and Mehrmann's
    ``E x' = A x + f``. lsc writes ``A x' + B x = f``; the result's
    ``.dae(u)`` converts: ``A_lsc = E``, ``B_lsc = -A``, ``f = B u(t)``.

    Parameters
    ----------
    source : str or os.PathLike or dict
        A MATLAB ``.mat`` file holding (at least) ``A`` and ``E`` (names
        case-insensitive; ``B``, ``C`` optional); or a Matrix Market prefix
        ``p``, read from ``p.E``, ``p.A``, ... (or ``p.E.mtx``,
        ``p_E.mtx``, ``pE.mtx``); or a dict name -> matrix or Matrix Market
        path. ``E`` missing means the identity (an ODE).

    Returns
    -------
    Descriptor

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np, scipy.io, scipy.sparse as sp
    >>> from lsc import gallery
    >>> p = gallery.msd_ind3(10, projectors=False)
    >>> d = tempfile.mkdtemp()
    >>> scipy.io.savemat(os.path.join(d, "msd.mat"), {"E": p.descriptor.E, "A": p.descriptor.A,
    ...                  "B": p.descriptor.B, "C": p.descriptor.C})
    >>> sys = gallery.read_descriptor(os.path.join(d, "msd.mat"))
    >>> sys.n, sys.B.shape
    (21, (21, 1))
    >>> dae = sys.dae(u=[1.0])           # E x' = A x + B u  ->  E x' - A x = B u
    >>> bool(abs(dae.B_sparse + p.descriptor.A).max() == 0)
    True
    """
    if isinstance(source, dict):
        raw = {}
        for key, value in source.items():
            up = str(key).upper()
            if up not in _NAMES:
                raise ValueError(f"`source` keys must be among {_NAMES}; found {key!r}.")
            raw[up] = scipy.io.mmread(os.fspath(value)) if isinstance(value, (str, os.PathLike)) else value
        where = "the given dict"
    else:
        path = os.fspath(source)
        if path.lower().endswith(".mat"):
            if not os.path.isfile(path):
                raise FileNotFoundError(f"`source` {path!r} does not exist.")
            raw, where = _from_mat(path), path
        else:
            raw, where = _from_matrix_market(path), f"Matrix Market files {path}.{{E,A,B,C}}"
    if "A" not in raw:
        raise ValueError(f"no matrix A found in {where} (expected names {_NAMES}, case-insensitive).")
    A = _matrix("A", raw["A"], where)
    n = A.shape[0]
    if A.shape != (n, n):
        raise DimensionError(f"`A` in {where} must be square: expected (n, n), got {A.shape}.")
    E = _matrix("E", raw["E"], where) if "E" in raw else sp.identity(n, format="csr")
    if E.shape != (n, n):
        raise DimensionError(f"`E` in {where} must have A's shape: expected {(n, n)}, got {E.shape}.")
    B = _matrix("B", raw["B"], where) if "B" in raw else None
    if B is not None and B.shape[0] != n:
        raise DimensionError(f"`B` in {where} must have n = {n} rows: expected ({n}, m), got {B.shape}.")
    C = _matrix("C", raw["C"], where) if "C" in raw else None
    if C is not None and C.shape[1] != n:
        raise DimensionError(f"`C` in {where} must have n = {n} columns: expected (p, {n}), got {C.shape}.")
    return Descriptor(E, A, B, C)
