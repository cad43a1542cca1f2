"""Exceptions and warnings raised by lsc.

Every class subclasses a builtin, so ``except ValueError`` keeps working for
callers that do not know about lsc.
"""

__all__ = ["DimensionError", "IndexDeterminationError", "RankDecisionWarning", "StiffnessWarning"]


class DimensionError(ValueError):
    """An array argument has the wrong shape.

    Messages say which argument, what was expected and what was found, e.g.
    ``expected (3, 3), got (3, 2)``.
    """


class IndexDeterminationError(ValueError):
    """No derivative array up to the allowed size determines ``x'``.

    Raised when the DAE is not uniquely solvable (for example a singular
    pencil), or when its differentiation index exceeds ``kmax``. The message
    lists every ``k`` tried and the ranks found.
    """


class RankDecisionWarning(UserWarning):
    """A numerical rank was decided with a small margin.

    Some singular value lies close to the threshold ``rcond * sigma_max``, so
    a slightly different ``rcond`` (or slightly perturbed data) could change
    the rank, the index and therefore the completion.
    """


class StiffnessWarning(UserWarning):
    """An explicit method was asked for on a stiff completion.

    Raised before the run starts, with the estimated number of right-hand
    side evaluations and time; ``method='auto'`` (or 'Radau', 'BDF', or
    'expm' for constant coefficients) avoids the cost.
    """
