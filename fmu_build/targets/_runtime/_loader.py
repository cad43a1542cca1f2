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
    """Make the host, Python or native, exit cleanly after loading this FMU's library.

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

    In a native host (a C or C++ program such as ecos or a C master)
    pythonfmu started the interpreter, and Python's ``atexit`` runs only inside
    the ``Py_Finalize`` that the first release triggers: too late. There the
    same function is registered with the C library's ``__cxa_atexit``: the
    FMU's library registered its static destructor when it was loaded, before
    any Python ran, and exit handlers run last registered first, so the state
    is released once, in order, before either (a C host: 20 of 20 runs
    aborted without it, in scipy's libgfortran ``close_units`` where the
    corrupted heap is first noticed; 0 of 20 with it). Linux only: the
    Windows binary frees its state from ``DllMain`` instead, which is not
    tested here.
    """
    import atexit
    import ctypes
    import os
    import sys

    if not sys.platform.startswith("linux") or resources is None:
        return
    path = os.path.join(os.path.dirname(os.path.abspath(resources)), "binaries", "linux64", model_identifier + ".so")
    if path in _EXIT_HOOKS or not os.path.exists(path):
        return
    try:
        library = ctypes.CDLL(path)  # the handle keeps it loaded (it is NODELETE anyway: C++ unique symbols)
        release = library.finalizePythonInterpreter
    except (OSError, AttributeError):
        return
    release.restype = None
    if sys.orig_argv:  # a Python host: Python's atexit runs before the C library's exit handlers
        atexit.register(release)
    else:  # pythonfmu's Py_Initialize leaves orig_argv empty: a native host
        try:
            cxa_atexit = getattr(ctypes.CDLL(None), "__cxa_atexit")  # getattr: no name mangling if moved into a class
        except AttributeError:  # not glibc's ABI: leave pythonfmu's own teardown
            return
        cxa_atexit.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        cxa_atexit.restype = ctypes.c_int
        # finalizePythonInterpreter(void) ignores the argument (x86-64 and aarch64 C ABIs);
        # no DSO handle: it runs at exit only
        if cxa_atexit(ctypes.cast(release, ctypes.c_void_p), None, None) != 0:
            return
    _EXIT_HOOKS.add(path)
