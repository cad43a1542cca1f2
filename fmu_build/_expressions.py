"""Safe parsing of spec expressions into sympy, without eval.

Only numbers, declared names (``t``, parameters), the operators
``+ - * / **`` and unary ``+ -``, parentheses, and calls of whitelisted
functions are accepted. The text is parsed with `ast` and converted node by
node; anything else (attribute access, subscripts, lambdas, comprehensions,
strings, unknown names or calls) is rejected with a message naming the
field and the offending construct.
"""

import ast

__all__ = ["ExpressionError", "FUNCTIONS", "parse_expression"]

# Whitelisted functions: name in a spec -> sympy attribute.
FUNCTIONS = {
    "sin": "sin", "cos": "cos", "tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan",
    "sinh": "sinh", "cosh": "cosh", "tanh": "tanh", "exp": "exp", "log": "log", "sqrt": "sqrt",
    "abs": "Abs", "atan2": "atan2",
}
CONSTANTS = {"pi": "pi", "e": "E"}


class ExpressionError(ValueError):
    """An expression in a spec is not allowed; the message names the field."""


def parse_expression(text, names, field):
    """Parse `text` into a sympy expression over the symbols in `names`.

    Parameters
    ----------
    text : str or number
        The expression (numbers pass through).
    names : dict
        Allowed identifiers -> sympy symbols (``t``, parameters, inputs).
    field : str
        Where the expression came from, for messages (e.g. ``equations.B[1][0]``).

    Examples
    --------
    >>> import sympy
    >>> t = sympy.Symbol("t")
    >>> parse_expression("2*sin(t)**2 + 1", {"t": t}, "f[0]")
    2*sin(t)**2 + 1
    >>> parse_expression("__import__('os')", {"t": t}, "f[0]")
    Traceback (most recent call last):
    ...
    fmu_build._expressions.ExpressionError: f[0]: call of '__import__' is not allowed (allowed functions: abs, acos, asin, atan, atan2, cos, cosh, exp, log, sin, sinh, sqrt, tan, tanh)
    """
    import sympy

    if isinstance(text, bool):
        raise ExpressionError(f"{field}: expected a number or an expression string, got a boolean")
    if isinstance(text, (int, float)):
        return sympy.Float(text) if isinstance(text, float) else sympy.Integer(text)
    if not isinstance(text, str):
        raise ExpressionError(f"{field}: expected a number or an expression string, got {type(text).__name__}")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"{field}: {text!r} is not a valid expression ({exc.msg})") from None
    return _convert(tree.body, names, field, sympy)


_BINOPS = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a**b,
}


def _convert(node, names, field, sympy):
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ExpressionError(f"{field}: constant {node.value!r} is not allowed (only numbers)")
        return sympy.Float(node.value) if isinstance(node.value, float) else sympy.Integer(node.value)
    if isinstance(node, ast.Name):
        if node.id in names:
            return names[node.id]
        if node.id in CONSTANTS:
            return getattr(sympy, CONSTANTS[node.id])
        raise ExpressionError(f"{field}: unknown name {node.id!r} (declared: {', '.join(sorted(names)) or 'none'})")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
        value = _convert(node.operand, names, field, sympy)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
        return _BINOPS[type(node.op)](_convert(node.left, names, field, sympy), _convert(node.right, names, field, sympy))
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name):
            raise ExpressionError(f"{field}: only plain function calls are allowed, found {ast.unparse(node.func)!r}")
        if node.func.id not in FUNCTIONS:
            raise ExpressionError(
                f"{field}: call of {node.func.id!r} is not allowed (allowed functions: {', '.join(sorted(FUNCTIONS))})"
            )
        if node.keywords:
            raise ExpressionError(f"{field}: keyword arguments are not allowed in {node.func.id}()")
        args = [_convert(a, names, field, sympy) for a in node.args]
        return getattr(sympy, FUNCTIONS[node.func.id])(*args)
    kind = {ast.Attribute: "attribute access", ast.Subscript: "subscripts", ast.Lambda: "lambdas"}.get(type(node), type(node).__name__)
    raise ExpressionError(f"{field}: {kind} not allowed in {ast.unparse(node)!r}")
