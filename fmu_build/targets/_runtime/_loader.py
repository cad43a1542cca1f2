"""Workarounds for two memory bugs of pythonfmu 0.7.0's loader (docs/reference/fmu-internals.md)."""

def give_back_loader_reference(module_globals):
    """Add one reference to a slave module's globals, owned by nobody.

    pythonfmu 0.7.0's ``findClass`` (PySlaveInstance.cpp) calls
    ``Py_DECREF`` on the *borrowed* result of ``PyModule_GetDict`` once per
    ``fmi2Instantiate``: the slave module's dict loses a reference it never
    lent. The slave script calls this at its top level, which runs at import
    and again at every instantiation (the loader re-executes the file), so
    the count stays one above the true number of owners: the dict is leaked
    at exit instead of being freed while still in use, which aborted hosts
    at exit with "corrupted double-linked list".
    """
    import ctypes

    try:
        incref = ctypes.pythonapi.Py_IncRef
    except AttributeError:  # a host without Python's C API symbols cannot run a pythonfmu FMU anyway
        return
    incref.argtypes = [ctypes.py_object]
    incref.restype = None
    incref(module_globals)


_EXIT_HOOKS = set()  # libraries whose loader state is already released at interpreter exit


def release_loader_state_at_exit(resources, model_identifier):
    """Make a Python host exit cleanly after loading this FMU's library.

    pythonfmu 0.7.0 keeps its interpreter guard in a static
    ``std::shared_ptr<PyState>`` and also resets it from an
    ``__attribute__((destructor))`` function. At process exit the C++ static
    destructor runs first (``__run_exit_handlers``) and the destructor
    function afterwards (``_dl_fini``), so the ``PyState`` is released twice
    (valgrind: "Invalid read ... in finalizePythonInterpreter", of a block
    freed by ``__run_exit_handlers``). The host then aborts with "corrupted
    double-linked list" or "free(): corrupted unsorted chunks"; measured in
    23 of 100 fmpy runs of one FMU. Calling the library's exported
    ``finalizePythonInterpreter`` from a Python ``atexit`` handler, which runs
    before both, leaves an empty pointer for them to release (0 of 100).

    Only where the host owns the interpreter: when pythonfmu started it (a
    native host such as ecos), its own thread finalizes Python and this hook
    must not run inside that. Linux only: the Windows binary frees its state
    from ``DllMain`` instead, which is not tested here.
    """
    import atexit
    import ctypes
    import os
    import sys

    if not sys.platform.startswith("linux") or not sys.orig_argv or resources is None:
        return  # not a Python host (pythonfmu's Py_Initialize leaves orig_argv empty)
    path = os.path.join(os.path.dirname(os.path.abspath(resources)), "binaries", "linux64", model_identifier + ".so")
    if path in _EXIT_HOOKS or not os.path.exists(path):
        return
    try:
        library = ctypes.CDLL(path)  # the handle keeps it loaded (it is NODELETE anyway: C++ unique symbols)
        release = library.finalizePythonInterpreter
    except (OSError, AttributeError):
        return
    release.restype = None
    atexit.register(release)
    _EXIT_HOOKS.add(path)
