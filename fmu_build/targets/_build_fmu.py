"""`build_fmu`: one front over the targets (checks the arguments, resolves the spec, picks the target)."""


from .._model import _resolve
from ..spec import MAX_K, METHODS, SpecError, derivative_problems, lam_problem, lam_value, model_name_problems

__all__ = ["build_fmu"]


def build_fmu(spec_or_dae, dest=".", *, method=None, lam=None, model_name=None, k=None, target="pythonfmu",
              fix_parameters=False, fmi_version=2, x0=None):
    """Build an FMI 2.0 Co-Simulation FMU of a linear DAE's completion.

    Parameters
    ----------
    spec_or_dae : path, dict or lsc.LinearDAE
        A TOML spec file, a parsed spec, or a LinearDAE (constant or sympy
        coefficients; states are named ``x[1]`` ... ``x[n]``). A LinearDAE of
        scipy.sparse coefficients (a large model) is built by the pythonfmu
        target with lsc's sparse set-up: the alternative completion, its
        forcing none, constant or an `lsc.InputForcing` whose inputs become
        the FMU's inputs ``u[1]`` ... (docs/guide/sparse.md); the native
        target refuses it.
    dest : path
        Folder (or ``.fmu`` file name) to write.
    method, lam, model_name, k : optional
        Override the spec's completion method, rate, model name and ``k``.
    target : {'pythonfmu', 'native'}, optional
        'pythonfmu' (default): Co-Simulation in Python, any coefficients.
        'native': generated C compiled with the system C compiler,
        Co-Simulation and Model Exchange in one FMU, no Python in the host;
        constant ``A`` and ``B``, or time-varying ones tabulated over the
        experiment's horizon (see docs/native_fmu.md).
    fix_parameters : bool, optional
        Native target: fix tunable parameters that enter ``A`` or ``B`` at
        their spec values instead of refusing the spec.
    fmi_version : {2, 3}, optional
        Native target: FMI 2.0 (default) or FMI 3.0 (Co-Simulation and Model
        Exchange over the same C core; see docs/native_fmu.md).
    x0 : array_like, shape (n,), optional
        A sparse LinearDAE's start values (default zeros; the FMU's parameters ``x_0[i]``).

    Returns
    -------
    pathlib.Path
        The FMU written.

    Raises
    ------
    SpecError
        Listing every problem of the spec.
    ValueError
        When `k`, `target` or `fmi_version` is out of range (a bad `model_name` is a `SpecError`, itself a ValueError).
    lsc.IndexDeterminationError
        When the DAE is not solvable: no FMU is written.

    Notes
    -----
    The FMU is made in a work folder next to it (``.lsc-build-<pid>-*``) and moved into place
    with one `os.replace`: a failed or interrupted build leaves the previous FMU (or none),
    never a part of one. A build killed outright leaves its work folder, which the next build
    into the same folder removes. The Python modules inside the FMU are named after a hash of
    its content, so FMUs with the same model name coexist in one process and a model may be
    named like any module; the caller's ``sys.modules`` is left as it was. See
    ``docs/reliability_fmu.md``.

    Examples
    --------
    >>> import tempfile
    >>> from fmpy.validation import validate_fmu
    >>> from fmu_build import build_fmu
    >>> spec = {"model": {"name": "Lag"}, "states": {"x": {"unit": "m"}},
    ...         "parameters": {"tau": {"value": 2.0, "unit": "s", "tunable": True}},
    ...         "equations": {"A": [["tau"]], "B": [[1]], "f": ["sin(t)"]}}
    >>> path = build_fmu(spec, tempfile.mkdtemp())
    >>> path.name, validate_fmu(str(path))
    ('Lag.fmu', [])
    """
    if getattr(spec_or_dae, "is_sparse", False):
        return _build_sparse(spec_or_dae, dest, method, lam, model_name, k, target, x0)
    if x0 is not None:
        raise ValueError("`x0` is for a sparse LinearDAE; a spec gives its states' start values.")
    spec = _resolve(spec_or_dae)
    if method is not None:
        if method not in METHODS:
            raise ValueError(f"`method` must be one of {METHODS}; found {method!r}.")
        spec.method = method
    if lam is not None:
        spec.lam = lam_value(lam)
        if lam_problem(spec.lam):
            raise ValueError(f"lam: {lam_problem(spec.lam)}")
    if model_name is not None:
        problems = model_name_problems(model_name, field="model_name")
        if problems:
            raise SpecError(problems, source="build_fmu")
        spec.name = model_name
    if k is not None:
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k <= MAX_K:
            raise ValueError(f"`k` must be an integer from 0 to {MAX_K}; found {k!r}.")
        spec.k = k
    if target not in ("pythonfmu", "native"):
        raise ValueError(f"`target` must be one of ('pythonfmu', 'native'); found {target!r}.")
    if type(fmi_version) is not int or fmi_version not in (2, 3):  # not True, not 3.0
        raise ValueError(f"`fmi_version` must be 2 or 3; found {fmi_version!r}.")
    if fmi_version == 3 and target != "native":
        raise ValueError("`fmi_version` 3 needs target='native' (the pythonfmu target writes FMI 2.0 only).")
    # k + 2 derivatives are taken symbolically; without completion.k, k is at most the index (<= n, <= 10)
    problems = derivative_problems(spec, (spec.k if spec.k is not None else min(spec.n, 10)) + 2)
    if problems:
        raise SpecError(problems, source=spec.name)
    if target == "native":
        from .native import build_native

        return build_native(spec, dest, fix_parameters=fix_parameters, fmi_version=fmi_version)
    from .pythonfmu import build_pythonfmu

    return build_pythonfmu(spec, dest)


def _build_sparse(dae, dest, method, lam, model_name, k, target, x0):
    """`build_fmu` for a LinearDAE of scipy.sparse coefficients."""
    n = dae.n
    if target == "native":
        from .native import NativeTargetError

        raise NativeTargetError(
            f"the native target refuses a sparse model (n = {n} unknowns): its C holds G and the forcing map as dense "
            f"arrays ({8.0 * n * n / 2**20:.3g} MiB for G alone) and steps with their exponential. Build it with "
            "target='pythonfmu' (lsc's sparse completion through sparse factorizations), or give dense arrays for a "
            "model small enough to hold densely.")
    if target != "pythonfmu":
        raise ValueError(f"`target` must be one of ('pythonfmu', 'native'); found {target!r}.")
    if method not in (None, "alternative"):
        raise ValueError(f"a sparse model has the 'alternative' completion only (docs/guide/sparse.md); found "
                         f"method={method!r}.")
    if model_name is not None:
        problems = model_name_problems(model_name, field="model_name")
        if problems:
            raise SpecError(problems, source="build_fmu")
    if k is not None and (isinstance(k, bool) or not isinstance(k, int) or not 0 <= k <= MAX_K):
        raise ValueError(f"`k` must be an integer from 0 to {MAX_K}; found {k!r}.")
    rate = 1.0 if lam is None else lam_value(lam)
    if lam_problem(rate):
        raise ValueError(f"lam: {lam_problem(rate)}")
    from .sparse_pythonfmu import build_sparse_pythonfmu

    return build_sparse_pythonfmu(dae, dest, lam=rate, model_name=model_name, k=k, x0=x0)
