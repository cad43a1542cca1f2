"""The FMI callbacks every FMU of the master receives, alive as long as the process.

fmpy's C logger proxy (``fmpy.logging.addLoggerProxy``) keeps ONE global
pointer to the last Python logger registered through it, and fmpy's own
``defaultCallbacks`` go through that proxy too. A logger dropped after a run
would leave that pointer dangling: the next FMU message anywhere in the
process would call freed memory. So the master registers one logger, once,
and keeps it (and the callback structure FMUs hold a pointer to) for the
process lifetime; each run adds a sink that receives its components'
messages while it runs. With no run active, a message goes to fmpy's default
printer, as it would without the master.
"""

import logging
import threading

logger = logging.getLogger("fmu_build.cosim")

_LEVELS = {0: logging.DEBUG, 1: logging.WARNING, 2: logging.WARNING, 3: logging.ERROR, 4: logging.CRITICAL}
_LOCK = threading.Lock()
_SINKS = []  # active runs' sinks, newest last
_STATE = {}  # "callbacks": the structure, "logger": the ctypes function (both never freed)


class _Sink:
    """Messages of one run's components: kept per component (the last 20), logged under its name."""

    def __init__(self, names):
        self.names = set(names)
        self.quiet = set()  # components whose messages go to DEBUG only (expected refusals)
        self.messages = {}

    def __call__(self, name, status, text):
        if name in self.quiet:
            logger.debug("[%s] %s", name, text)
            return
        self.messages.setdefault(name, []).append(text)
        del self.messages[name][:-20]
        logger.log(_LEVELS.get(status, logging.INFO), "[%s] %s", name, text)


def _log(env, instance, status, category, message):
    """The one Python logger behind fmpy's proxy (the proxy has formatted the variadic message)."""
    name = instance.decode(errors="replace") if instance else "?"
    text = message.decode(errors="replace") if message else ""
    with _LOCK:
        sink = next((s for s in reversed(_SINKS) if name in s.names), None)
    if sink is not None:
        sink(name, status, text)
        return
    try:
        from fmpy.fmi2 import printLogMessage

        printLogMessage(env, instance, status, category, message)
    except Exception:  # noqa: BLE001 -- a logger must never raise into the FMU
        pass


def callbacks():
    """The process-wide ``fmi2CallbackFunctions`` (created and proxied on first use, never freed)."""
    with _LOCK:
        if "callbacks" in _STATE:
            return _STATE["callbacks"]
        from ctypes import byref

        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

        structure = fmi2CallbackFunctions()
        _STATE["logger"] = fmi2CallbackLoggerTYPE(_log)
        structure.logger = _STATE["logger"]
        structure.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        structure.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(byref(structure))
        except Exception as exc:  # noqa: BLE001 -- fmpy without its logging library
            logger.warning("fmpy's logger proxy is not available (%s): C FMUs' messages are not formatted", exc)
        _STATE["callbacks"] = structure
        return structure


def fmi3_logger(name):
    """The Python side of an FMI 3.0 instance's log message callback: ``log(status, message)`` routes the
    (formatted) message of instance ``name`` as `_log` routes FMI 2.0's. FMI 3.0 needs no proxy: fmpy keeps
    the ctypes callback on the slave, alive as long as the instance."""

    def log(status, message):
        try:
            text = message.decode(errors="replace") if isinstance(message, bytes) else str(message or "")
            with _LOCK:
                sink = next((s for s in reversed(_SINKS) if name in s.names), None)
            if sink is not None:
                sink(name, status, text)
            else:
                logger.log(_LEVELS.get(status, logging.INFO), "[%s] %s", name, text)
        except Exception:  # noqa: BLE001 -- a logger must never raise into the FMU
            pass

    return log


class attach:
    """Context manager: route the messages of the components ``names`` to a new sink while it is open.

    Examples
    --------
    >>> with attach(["a"]) as sink:
    ...     sink("a", 0, "hello")
    >>> sink.messages
    {'a': ['hello']}
    """

    def __init__(self, names):
        self.sink = _Sink(names)

    def __enter__(self):
        with _LOCK:
            _SINKS.append(self.sink)
        return self.sink

    def __exit__(self, *exc):
        with _LOCK:
            _SINKS.remove(self.sink)
        return False
