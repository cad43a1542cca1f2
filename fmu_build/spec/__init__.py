"""The declarative FMU spec: TOML -> a validated `ModelSpec` (no code executed).

`_spec` reads and checks the spec, `_expressions` parses its expressions
(a whitelist of functions, no code run) and `_limits` bounds what a spec may
ask (sizes, rates, derivatives) so that a build cannot run away.
"""

from ._expressions import ExpressionError
from ._limits import MAX_K, derivative_problems, lam_problem, lam_value
from ._spec import METHODS, ModelSpec, SpecError, load_spec, model_name_problems, parse_spec

__all__ = ["ExpressionError", "METHODS", "MAX_K", "ModelSpec", "SpecError", "derivative_problems", "lam_problem", "lam_value",
           "load_spec", "model_name_problems", "parse_spec"]
