"""FMU targets over one numeric model (`fmu_build._model`): `build_fmu` picks one.

`pythonfmu`: the completion in Python, any coefficients (its runtime package
`_runtime` is copied into each FMU). `native`: generated C, constant ``A``
and ``B``, FMI 2.0 Co-Simulation and Model Exchange in one FMU.
"""

from ._build_fmu import build_fmu
from .native import NativeTargetError

__all__ = ["build_fmu", "NativeTargetError"]
