"""lsc and scipy's ODE solvers for the runtime: the FMU's private copies inside a built FMU.

Inside a built FMU this package is ``<lsc copy>._fmu_runtime``: the parent
package is the FMU's own copy of lsc, read through its public names only,
and scipy's solvers are copied into ``_scipy_ivp`` next to this module (see
`fmu_build.targets._vendor`), so the FMU never imports ``scipy.integrate``.
Imported from fmu_build itself (documentation, tests), the parent is
``fmu_build.targets`` and the installed lsc and scipy are used.
"""

try:  # inside a built FMU: scipy's solvers without importing scipy.integrate
    from ._scipy_ivp import BDF, DOP853, RK45, Radau
except ImportError:
    from scipy.integrate import BDF, DOP853, RK45, Radau

try:  # inside a built FMU this package sits in the private copy of lsc
    from .. import COMPLETIONS, ExactPropagator, JetCallable, LinearDAE, complete
except ImportError:  # imported from fmu_build itself (documentation, tests)
    from lsc import COMPLETIONS, ExactPropagator, JetCallable, LinearDAE, complete

__all__ = ["BDF", "DOP853", "RK45", "Radau", "LinearDAE", "complete", "ExactPropagator", "JetCallable", "COMPLETIONS",
           "input_forcing_class"]


def input_forcing_class():
    """``lsc.InputForcing``, for a sparse model's FMU only (a dense model's copy of lsc has no sparse set-up)."""
    try:
        from .. import InputForcing
    except ImportError:
        from lsc import InputForcing
    return InputForcing
