"""fmu_build: package an lsc completion as an FMI 2.0 Co-Simulation FMU (pythonfmu)."""
from .cosim import cosimulate
from ._host import ecos_executable, native_host_env
from ._input_tables import InputFit, fit_inputs, simulate_with_inputs
from .spec import ExpressionError, ModelSpec, SpecError, load_spec, parse_spec
from .targets import NativeTargetError, build_fmu
from .study import plot_study, recommend, sweep

__all__ = ["build_fmu", "cosimulate", "load_spec", "parse_spec", "ModelSpec", "SpecError", "ExpressionError",
           "native_host_env", "ecos_executable", "NativeTargetError", "sweep", "recommend", "plot_study",
           "InputFit", "fit_inputs", "simulate_with_inputs"]
