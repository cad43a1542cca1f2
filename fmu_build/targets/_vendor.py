"""scipy's pure-Python ODE solvers, copied into a pythonfmu FMU without ``import scipy.integrate``."""

import shutil
from pathlib import Path

_IVP_FILES = ("base.py", "common.py", "rk.py", "dop853_coefficients.py", "radau.py", "bdf.py")


_LAZY_SCIPY = """\
\"\"\"Lazy stand-ins for the scipy.sparse / scipy.optimize names the copied solvers import.

Only sparse Jacobians use them, and lsc passes dense ones, so in an FMU they
are never called and those packages (and their compiled extensions, which
misbehave when an embedded interpreter is finalized) are never loaded. If
one is called, the real function is imported then.
\"\"\"


def issparse(x):
    return type(x).__module__.startswith("scipy.sparse")


def _sparse():
    import scipy.sparse

    return scipy.sparse


def csc_matrix(*args, **kwargs):
    return _sparse().csc_matrix(*args, **kwargs)


def coo_matrix(*args, **kwargs):
    return _sparse().coo_matrix(*args, **kwargs)


def eye(*args, **kwargs):
    return _sparse().eye(*args, **kwargs)


def find(*args, **kwargs):
    return _sparse().find(*args, **kwargs)


def splu(*args, **kwargs):
    import scipy.sparse.linalg

    return scipy.sparse.linalg.splu(*args, **kwargs)


def group_columns(*args, **kwargs):
    from scipy.optimize._numdiff import group_columns

    return group_columns(*args, **kwargs)
"""


def _vendor_ivp(dest):
    """Copy scipy's pure-Python ODE solvers into the FMU, importing only numpy and scipy.linalg.

    ``import scipy.integrate`` pulls in scipy.optimize and scipy.fft, hence
    scipy._lib._uarray, whose objects are freed wrongly when an embedded
    interpreter is finalized: the native host ecos then segfaulted at exit
    (gdb: ``_uarray Function::clear`` in ``Py_FinalizeEx``); scipy.sparse.linalg
    (SuperLU, ARPACK, PROPACK) aborted it once in a bisection too. The solver
    modules need numpy and scipy.linalg, plus scipy.sparse / scipy.optimize
    names that only sparse Jacobians use (lsc passes dense ones); those
    imports are redirected to lazy stand-ins. The copies come from the
    installed scipy at build time (BSD licence, included). Returns False, and
    the runtime falls back to scipy.integrate, if scipy's layout differs.
    """
    import re

    import scipy

    ivp = Path(scipy.__file__).parent / "integrate" / "_ivp"
    if not all((ivp / f).exists() for f in _IVP_FILES):
        return False
    pattern = re.compile(r"^from scipy\.(sparse|sparse\.linalg|optimize\._numdiff) import (.+)$", re.M)
    texts = {f: pattern.sub(r"from ._lazy_scipy import \2", (ivp / f).read_text()) for f in _IVP_FILES}
    if any(re.search(r"^\s*(from|import) scipy\.(sparse|optimize|integrate|fft)", t, re.M) for t in texts.values()):
        return False  # an import this function does not know how to keep out
    dest.mkdir()
    for f, text in texts.items():
        (dest / f).write_text(text)
    (dest / "_lazy_scipy.py").write_text(_LAZY_SCIPY)
    (dest / "__init__.py").write_text(
        '"""scipy.integrate._ivp solvers, copied at FMU build time (scipy is BSD-licensed: see LICENSE.txt)."""\n'
        "from .rk import RK45, DOP853\nfrom .radau import Radau\nfrom .bdf import BDF\n"
    )
    licence = next(Path(scipy.__file__).parent.parent.glob("scipy-*.dist-info/LICENSE*"), None)
    if licence is not None:
        shutil.copy(licence, dest / "LICENSE.txt")
    return True

