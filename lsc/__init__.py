"""lsc: least squares completions of linear DAEs, with chosen extra dynamics."""
from ._completion import COMPLETIONS, AlternativeCompletion, Completion, StabilizedCompletion, StandardCompletion, complete
from ._derivative_array import DerivativeArray, derivative_array
from ._exceptions import DimensionError, IndexDeterminationError, RankDecisionWarning
from ._index import SolvabilityReport, check_solvability, differentiation_index
from ._problem import LinearDAE
from ._analysis import Eigenanalysis, eigenanalysis
from ._integrate import CompletionResult, solve_completion, solve_dae
from . import gallery
