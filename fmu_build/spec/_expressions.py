"""Safe parsing of spec expressions into sympy, without eval.

Only numbers, declared names (``t``, parameters), the operators
``+ - * / **`` and unary ``+ -``, parentheses, and calls of whitelisted
functions are accepted. The text is parsed with `ast` and converted node by
node; anything else (attribute access, subscripts, lambdas, comprehensions,
strings, unknown names or calls) is rejected with a message naming the
field and the offending construct.

The work is bounded whatever the text: at most `MAX_LENGTH` characters and
`MAX_DEPTH` levels of nesting; every number, given or computed from numbers,
lies within the range of a double (`MAX_MAGNITUDE`); a numeric exponent is at
most `MAX_EXPONENT` in magnitude, and a power of two numbers is refused
before it is computed when its result would leave that range (``9**9**9``
would otherwise take sympy hours). Results that are not finite (``1/0``) or
not real (``log(-1)``) are refused too.
"""

import ast
import math

__all__ = ["ExpressionError", "FUNCTIONS", "CONSTANTS", "MAX_LENGTH", "MAX_DEPTH", "MAX_EXPONENT", "MAX_MAGNITUDE",
           "MAX_DEGREE", "parse_expression", "evaluate"]

MAX_LENGTH = 10_000  # characters of one expression
MAX_DEPTH = 100  # nesting of operators and calls
MAX_EXPONENT = 1000  # magnitude of a numeric exponent
MAX_MAGNITUDE = 1e308  # every number (a double's range)
MAX_DEGREE = MAX_EXPONENT  # total polynomial degree of an expression, products included

# Whitelisted functions: name in a spec -> sympy attribute.
FUNCTIONS = {
    "sin": "sin", "cos": "cos", "tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan",
    "sinh": "sinh", "cosh": "cosh", "tanh": "tanh", "exp": "exp", "log": "log", "sqrt": "sqrt",
    "abs": "Abs", "atan2": "atan2",
}
CONSTANTS = {"pi": "pi", "e": "E"}
# number of arguments of each function
ARITY = {name: 2 if name == "atan2" else 1 for name in FUNCTIONS}


class ExpressionError(ValueError):
    """An expression in a spec is not allowed; the message names the field."""


def parse_expression(text, names, field, *, differentiated=False):
    """Parse `text` into a sympy expression over the symbols in `names`.

    Parameters
    ----------
    text : str or number
        The expression (numbers pass through).
    names : dict
        Allowed identifiers -> sympy symbols (``t``, parameters, inputs).
    field : str
        Where the expression came from, for messages (e.g. ``equations.B[1][0]``).
    differentiated : bool, optional
        The expression will be differentiated in time (the equations' ``A``, ``B``, ``f``):
        functions without a derivative where their argument vanishes (``abs``) are refused.

    Examples
    --------
    >>> import sympy
    >>> t = sympy.Symbol("t")
    >>> parse_expression("2*sin(t)**2 + 1", {"t": t}, "f[0]")
    2*sin(t)**2 + 1
    >>> parse_expression("__import__('os')", {"t": t}, "f[0]")
    Traceback (most recent call last):
    ...
    fmu_build.spec._expressions.ExpressionError: f[0]: call of '__import__' is not allowed (allowed functions: abs, acos, asin, atan, atan2, cos, cosh, exp, log, sin, sinh, sqrt, tan, tanh)
    """
    import sympy

    if isinstance(text, bool):
        raise ExpressionError(f"{field}: expected a number or an expression string, got a boolean")
    if isinstance(text, (int, float)):
        return _number(text, field, sympy)
    if not isinstance(text, str):
        raise ExpressionError(f"{field}: expected a number or an expression string, got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"{field}: expression of {len(text)} characters is too long (at most {MAX_LENGTH})")
    for i, ch in enumerate(text):
        # Python's parser NFKC-normalizes identifiers: fullwidth "ｔａｕ" would silently mean tau
        if not ch.isascii():
            raise ExpressionError(f"{field}: non-ASCII character {ch!r} (U+{ord(ch):04X}) at position {i}; "
                                  f"names, numbers and operators in expressions are ASCII")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"{field}: {_short(text)!r} is not a valid expression ({exc.msg})") from None
    except ValueError as exc:  # e.g. a null character
        raise ExpressionError(f"{field}: {_short(text)!r} is not a valid expression ({exc})") from None
    except (RecursionError, MemoryError):
        raise ExpressionError(f"{field}: expression nested too deeply or too long a chain of operators "
                              f"(at most {MAX_DEPTH} levels of nesting)") from None
    depth = _depth(tree.body)
    if depth > MAX_DEPTH:
        raise ExpressionError(f"{field}: expression nested {depth} levels deep (at most {MAX_DEPTH})")
    try:
        expr = _convert(tree.body, names, field, sympy)
    except ExpressionError:
        raise
    except (TypeError, ValueError, ArithmeticError, RecursionError, MemoryError) as exc:
        raise ExpressionError(f"{field}: {_short(text)!r} cannot be converted ({type(exc).__name__}: {exc})") from None
    _check_result(expr, text, field, sympy)
    _check_size(expr, text, field, sympy)
    if differentiated:
        _check_differentiable(expr, field, sympy)
    return expr


def _check_differentiable(expr, field, sympy):
    """Refuse ``abs`` where derivatives are needed: at a zero of its argument it has none.

    The completion differentiates every coefficient up to order k + 2 (and an input's derivatives
    enter by the chain rule); the derivative of ``abs(u)`` is ``sign(u) u'``, which jumps where
    ``u = 0``, and its own derivative is a Dirac delta there. Whether ``u`` vanishes during a run
    cannot be known when an input or a parameter enters it, so ``abs`` is refused in the equations
    (outputs are only evaluated, and may use it).
    """
    if expr.has(sympy.Abs):
        raise ExpressionError(
            f"{field}: abs() is not allowed in the equations: the completion differentiates A, B and f in time "
            "(up to order k + 2), and abs(u) has no derivative where u = 0 (its first derivative jumps, its second is "
            "infinite there). Use a smooth alternative, e.g. sqrt(u**2 + eps**2) with a small eps (a parameter), or "
            "split the simulation where u changes sign; abs() is allowed in [outputs]"
        )


def _short(text, limit=80):
    return text if len(text) <= limit else text[:limit] + "..."


def _depth(node):
    """Nesting depth of an ast, without recursion (a deep tree must not overflow the stack)."""
    deepest, stack = 0, [(node, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        if depth <= MAX_DEPTH:  # deeper is refused anyway: stop walking
            for child in ast.iter_child_nodes(node):
                # a chain a + b - c + ... (or a * b / c ...) is one level: it is converted in a loop
                chained = child is getattr(node, "left", None) and _group(node) and _group(child) == _group(node)
                stack.append((child, depth if chained else depth + 1))
    return deepest


def _number(value, field, sympy):
    """A sympy number from a Python int or float, refused outside the range of a double."""
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ExpressionError(f"{field}: number {value!r} is not finite")
        return sympy.Float(value)
    if abs(value) > MAX_MAGNITUDE:
        raise ExpressionError(f"{field}: integer with {len(str(abs(value)))} digits is out of range (at most {MAX_MAGNITUDE:g})")
    return sympy.Integer(value)


def _check_number(value, field, sympy):
    """Refuse a computed number that left the range of a double (or is not finite)."""
    if value.is_Number and (value.is_finite is False or value is sympy.nan):
        raise ExpressionError(f"{field}: a value in the expression is not finite (a division by zero?)")
    if value.is_Number and abs(value) > MAX_MAGNITUDE:
        raise ExpressionError(f"{field}: a number in the expression is out of range (at most {MAX_MAGNITUDE:g} in magnitude)")
    return value


def _power(base, exponent, field, sympy):
    """``base**exponent``, refused before computing when the exponent or the result is too large."""
    if exponent.is_Number:
        if exponent.is_finite and abs(exponent) > MAX_EXPONENT:
            raise ExpressionError(f"{field}: exponent {_short(str(exponent), 30)} is too large (at most {MAX_EXPONENT} in magnitude)")
        if base.is_Number and base.is_negative and not exponent.is_integer:
            raise ExpressionError(f"{field}: ({base})**({exponent}) is not real (a fractional power of a negative number)")
        if base.is_Number and base.is_finite and exponent.is_finite and base != 0:
            size = abs(float(exponent)) * abs(math.log10(abs(float(base))))
            if size > math.log10(MAX_MAGNITUDE):
                raise ExpressionError(f"{field}: {base}**{exponent} is out of range (at most {MAX_MAGNITUDE:g} in magnitude)")
    return base**exponent


def _check_result(expr, text, field, sympy):
    """Refuse an expression that is not finite (``1/0``) or not real (``log(-1)``)."""
    bad = {sympy.zoo, sympy.oo, -sympy.oo, sympy.nan}
    if any(a in bad for a in expr.atoms()) or expr in bad:
        raise ExpressionError(f"{field}: {_short(text)!r} is not finite (a division by zero?)")
    if expr.has(sympy.I):
        raise ExpressionError(f"{field}: {_short(text)!r} is not real (e.g. the log or sqrt of a negative number)")


def _degree(expr, memo):
    """Total degree of `expr` as a polynomial in its symbols; a function counts as its argument.

    Products combine into powers (``t**1000*t**1000`` is ``t**2000``, 1600 factors ``(t+1)`` are
    ``(t+1)**1600``), so the exponent limit alone does not bound the degree.
    """
    if expr in memo:
        return memo[expr]
    if expr.is_Symbol:
        value = 1
    elif expr.is_Number or expr.is_NumberSymbol or not expr.args:
        value = 0
    elif expr.is_Mul:
        value = sum(_degree(a, memo) for a in expr.args)
    elif expr.is_Pow and expr.exp.is_Number:
        value = _degree(expr.base, memo) * abs(float(expr.exp))
    elif expr.is_Pow:
        value = _degree(expr.base, memo) + _degree(expr.exp, memo)
    else:  # Add, functions
        value = max(_degree(a, memo) for a in expr.args)
    memo[expr] = value
    return value


def _check_size(expr, text, field, sympy):
    """Refuse an expression whose degree (after sympy combined its factors) is too large."""
    if expr.is_Number:
        return
    degree = _degree(expr, {})
    if degree > MAX_DEGREE:
        raise ExpressionError(f"{field}: {_short(text)!r} has total degree {degree:g} in t, the parameters and the "
                              f"inputs (at most {MAX_DEGREE}; products count: t**1000*t**1000 is t**2000)")


def _group(node):
    """'add' for ``+ -``, 'mul' for ``* /``, else None."""
    if isinstance(node, ast.BinOp):
        if isinstance(node.op, (ast.Add, ast.Sub)):
            return "add"
        if isinstance(node.op, (ast.Mult, ast.Div)):
            return "mul"
    return None


def _convert(node, names, field, sympy):
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ExpressionError(f"{field}: constant {_short(repr(node.value))} is not allowed (only numbers)")
        return _number(node.value, field, sympy)
    if isinstance(node, ast.Name):
        if node.id in names:
            return names[node.id]
        if node.id in CONSTANTS:
            return getattr(sympy, CONSTANTS[node.id])
        raise ExpressionError(f"{field}: unknown name {node.id!r} (declared: {', '.join(sorted(names)) or 'none'})")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
        value = _convert(node.operand, names, field, sympy)
        return -value if isinstance(node.op, ast.USub) else value
    if _group(node):
        # a chain a + b - c + ... in one sympy call: a loop, not a recursion per term
        group, terms = _group(node), []
        while _group(node) == group:
            terms.append((type(node.op), node.right))
            node = node.left
        terms.append((None, node))
        args = []
        for op, operand in reversed(terms):
            value = _convert(operand, names, field, sympy)
            args.append(-value if op is ast.Sub else value**-1 if op is ast.Div else value)
        return _check_number(sympy.Add(*args) if group == "add" else sympy.Mul(*args), field, sympy)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
        left, right = _convert(node.left, names, field, sympy), _convert(node.right, names, field, sympy)
        return _check_number(_power(left, right, field, sympy), field, sympy)
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name):
            raise ExpressionError(f"{field}: only plain function calls are allowed, found {_short(ast.unparse(node.func))!r}")
        if node.func.id not in FUNCTIONS:
            raise ExpressionError(
                f"{field}: call of {node.func.id!r} is not allowed (allowed functions: {', '.join(sorted(FUNCTIONS))})"
            )
        if node.keywords:
            raise ExpressionError(f"{field}: keyword arguments are not allowed in {node.func.id}()")
        if any(isinstance(a, ast.Starred) for a in node.args):
            raise ExpressionError(f"{field}: starred arguments are not allowed in {node.func.id}()")
        if len(node.args) != ARITY[node.func.id]:
            want = ARITY[node.func.id]
            raise ExpressionError(f"{field}: {node.func.id}() takes {want} argument{'s' if want > 1 else ''}, "
                                  f"got {len(node.args)}")
        args = [_convert(a, names, field, sympy) for a in node.args]
        return _check_number(getattr(sympy, FUNCTIONS[node.func.id])(*args), field, sympy)
    kind = {ast.Attribute: "attribute access", ast.Subscript: "subscripts", ast.Lambda: "lambdas"}.get(type(node), type(node).__name__)
    raise ExpressionError(f"{field}: {kind} not allowed in {_short(ast.unparse(node))!r}")


_MATH = {"sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin, "acos": math.acos, "atan": math.atan,
         "sinh": math.sinh, "cosh": math.cosh, "tanh": math.tanh, "exp": math.exp, "log": math.log, "Abs": abs,
         "atan2": math.atan2}


def evaluate(expr, values):
    """The value of a parsed expression as a float, in double arithmetic.

    Parameters
    ----------
    expr : sympy expression
        From `parse_expression` (numbers, symbols, ``+ * **``, the whitelisted functions).
    values : dict
        Symbol -> float, for every free symbol.

    Returns
    -------
    float

    Raises
    ------
    ArithmeticError, ValueError
        When the value is not finite or not real (``1/t`` at ``t = 0``, ``log`` of a
        negative number): `ZeroDivisionError`, `OverflowError` or a math domain error.

    Examples
    --------
    >>> import sympy
    >>> t = sympy.Symbol("t")
    >>> evaluate(parse_expression("2*sin(t) + 1", {"t": t}, "f[0]"), {t: 0.0})
    1.0
    >>> evaluate(parse_expression("1/t", {"t": t}, "f[0]"), {t: 0.0})
    Traceback (most recent call last):
    ...
    ZeroDivisionError: 0.0 cannot be raised to a negative power
    """
    value = _evaluate(expr, values)
    if isinstance(value, complex) or not math.isfinite(value):
        raise ValueError(f"value {value!r} is not a finite real number")
    return float(value)


def _evaluate(expr, values):
    """Float arithmetic on the sympy tree (never sympy's arbitrary precision: bounded time)."""
    if expr.is_Symbol:
        return float(values[expr])
    if expr.is_Number or expr.is_NumberSymbol:
        return float(expr)
    args = [_evaluate(a, values) for a in expr.args]
    if expr.is_Add:
        return math.fsum(args)
    if expr.is_Mul:
        return math.prod(args)
    if expr.is_Pow:
        base, exponent = args
        if base < 0 and not float(exponent).is_integer():
            raise ValueError(f"{base!r}**{exponent!r} is not real")
        return float(base**exponent)
    name = type(expr).__name__
    if name in _MATH:
        return float(_MATH[name](*args))
    raise ValueError(f"cannot evaluate {name} numerically")
