"""What a spec may ask: bounds that keep every build short and every number meaningful in doubles.

`lam_problem` and `derivative_problems` are also used by `build_fmu`, for the
values it is given besides the spec.
"""

import math
import numbers

MAX_NAME = 100  # characters of a state, parameter, input or output name
MAX_MODEL_NAME = 64  # characters of the model name (it names files and a class)
MAX_TEXT = 10_000  # characters of a description or unit
MAX_K = 20  # differentiations: a bound against runaway builds, not a statement of accuracy
# completion.lam: powers of lam up to lam**(k+1) enter the completion's coefficients; beyond this
# they overflow a double or swamp the model's own coefficients (a decay of exp(-1e12 t) is
# already complete within any step a double can tell from zero time).
MAX_LAM = 1e12
# Nodes of each derivative of an entry of A, B, f up to the order the completion needs: a bound
# that keeps every build short (derivatives of some short texts grow exponentially).
MAX_DERIVATIVE_SIZE = 2000
# experiment.step relative to the largest |time|: a smaller step is lost in the rounding of the
# time (1e20 + 0.01 == 1e20); a double carries about 16 significant digits.
MIN_RELATIVE_STEP = 1e-12


def lam_value(lam):
    """`lam` as a float when it is a positive finite real number; a TypeError or ValueError naming it otherwise.

    Examples
    --------
    >>> lam_value(2)
    2.0
    """
    if isinstance(lam, bool) or not isinstance(lam, numbers.Real):
        raise TypeError(f"`lam` must be a positive finite real number; found {lam!r}.")
    value = float(lam)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"`lam` must be a positive finite real number; found {lam!r}.")
    return value


def lam_problem(lam):
    """Why the rate `lam` (a positive finite float) cannot be used, or None.

    Examples
    --------
    >>> lam_problem(2.0) is None
    True
    >>> lam_problem(1e308)
    'must be at most 1e+12, got 1e+308: powers of lam up to lam**(k+1) enter the completion and would overflow or swamp the model in double arithmetic'
    """
    if lam > MAX_LAM:
        return (f"must be at most {MAX_LAM:g}, got {lam!r}: powers of lam up to lam**(k+1) enter the completion "
                f"and would overflow or swamp the model in double arithmetic")
    return None


def _size(expr, limit):
    """Number of nodes of a sympy expression tree, counted up to just past `limit` (no recursion)."""
    count, stack = 0, [expr]
    while stack and count <= limit:
        node = stack.pop()
        count += 1
        stack.extend(node.args)
    return count


def derivative_problems(spec, order):
    """Entries of A, B, f whose derivatives up to `order` grow beyond `MAX_DERIVATIVE_SIZE` nodes.

    The completion differentiates every coefficient up to order k + 2 symbolically; some short
    texts have derivatives that grow exponentially with the order (a product of 40 factors,
    nested functions). Each entry is differentiated one order at a time and abandoned as soon
    as a derivative is too large, so the check itself stays short. Inputs count as functions of
    ``t`` (their derivatives enter by the chain rule), parameters as symbols.

    Returns a list of messages naming the field and the order, empty when every entry is fine.
    """
    import sympy

    t = spec.t
    as_functions = {u: sympy.Function(f"_lsc_fn_{name}")(t) for name, u in spec.input_symbols.items()}
    problems = []
    for label, M, vector in (("A", spec.A, False), ("B", spec.B, False), ("f", spec.f, True)):
        for i in range(M.rows):
            for j in range(M.cols):
                expr = M[i, j].subs(as_functions) if as_functions else M[i, j]
                for d in range(1, order + 1):
                    if not expr.has(t):
                        break
                    expr = expr.diff(t)
                    size = _size(expr, MAX_DERIVATIVE_SIZE)
                    if size > MAX_DERIVATIVE_SIZE:
                        where = f"equations.{label}[{i}]" if vector else f"equations.{label}[{i}][{j}]"
                        problems.append(f"{where}: its derivative of order {d} has more than {MAX_DERIVATIVE_SIZE} "
                                        f"terms and operations (the completion needs derivatives up to order {order}; "
                                        f"a product of many factors or deeply nested functions grows exponentially "
                                        f"when differentiated): simplify it, or lower completion.k")
                        break
    return problems
