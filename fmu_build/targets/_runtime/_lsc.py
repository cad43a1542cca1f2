"""lsc and scipy's ODE solvers for the runtime: the FMU's private copies inside a built FMU.

Inside a built FMU this package is ``<lsc copy>._fmu_runtime``: the parent
package is the FMU's own copy of lsc, with scipy's solvers copied into its
``_scipy_ivp`` (see `fmu_build.targets._vendor`), so the FMU never imports
``scipy.integrate``. Imported from fmu_build itself (documentation, tests),
the parent is ``fmu_build.targets`` and the installed lsc and scipy are used.
"""

try:  # inside a built FMU: scipy's solvers without importing scipy.integrate
    from .._scipy_ivp import BDF, DOP853, RK45, Radau
except ImportError:
    from scipy.integrate import BDF, DOP853, RK45, Radau

try:  # inside a built FMU this package sits in the private copy of lsc
    from .. import LinearDAE, complete
    from .._expm import Propagator
    from .._timefunc import JetCallable
except ImportError:  # imported from fmu_build itself (documentation, tests)
    from lsc import LinearDAE, complete
    from lsc._expm import Propagator
    from lsc._timefunc import JetCallable

__all__ = ["BDF", "DOP853", "RK45", "Radau", "LinearDAE", "complete", "Propagator", "JetCallable"]
