"""The FMI guard: pythonfmu's `Fmi2Slave` with every FMI method made safe (never raises)."""

import functools
import json

def _never_raises(fallback):
    """Decorate an FMI method of `LscSlave`: an exception is logged as an fmi2Error message and
    ``fallback(self, *args)`` is returned instead (pythonfmu would make it fatal)."""

    def decorate(method):
        @functools.wraps(method)
        def safe(self, *args):
            try:
                return method(self, *args)
            except Exception as exc:
                try:
                    self.lsc_log_error(f"{method.__name__} failed: {type(exc).__name__}: {exc}")
                    return fallback(self, *args)
                except Exception:
                    return None
        return safe
    return decorate


def _article(word):
    return ("an " if word[0] in "AEIOU" else "a ") + word


def _values_like(value):
    return lambda self, vrs, *rest: [value] * len(vrs)


def _nothing(self, *args):
    return None


_SLAVE_BASE = []


def make_slave_base():
    """The base class of every generated slave: pythonfmu's `Fmi2Slave` with every FMI method made safe.

    A function, so that importing this module needs no pythonfmu (the build imports it); the
    class is made once per copy of this module (the slave script runs at every instantiation).
    """
    if not _SLAVE_BASE:
        _SLAVE_BASE.append(_make_slave_base())
    return _SLAVE_BASE[0]


class _SafeMethods:
    """Every FMI method of `LscSlave`: delegates to `LscRuntime` (``self.rt``) and never raises.

    A plain class, so that importing this module needs no pythonfmu (the build imports it);
    `_make_slave_base` puts it in front of pythonfmu's `Fmi2Slave` and gives it pythonfmu's
    variable classes and error status.
    """

    rt = None
    _lsc_kinds = {}  # pythonfmu variable class -> its FMI type name (set by _make_slave_base)
    _lsc_types = {}  # FMI type name -> pythonfmu variable class
    _lsc_error = None  # pythonfmu's Fmi2Status.error

    def lsc_log_error(self, msg):
        self.log(msg, status=self._lsc_error)

    def _variable(self, vr, kind):
        var = self.vars.get(vr)
        if var is None:
            self.lsc_log_error(f"unknown value reference {vr}: this FMU has 0..{len(self.vars) - 1}")
        elif not isinstance(var, kind):
            kinds = self._lsc_kinds
            self.lsc_log_error(f"{var.name!r} is a {kinds[type(var)]}, not {_article(kinds[kind])} (value reference {vr}): "
                               "the call is ignored for it")
            return None
        return var

    def _get(self, vrs, kind, convert, bad):
        out = []
        for vr in vrs:
            var = self._variable(vr, kind)
            try:
                out.append(convert(var.getter()) if var is not None else bad)
            except Exception as exc:
                self.lsc_log_error(f"reading {var.name!r} failed: {type(exc).__name__}: {exc}")
                out.append(bad)
        return out

    def _set(self, vrs, values, kind):
        for vr, value in zip(vrs, values):
            var = self._variable(vr, kind)
            if var is None:
                continue
            problem = self.rt.settable(var) if self.rt is not None else None
            if problem:
                self.lsc_log_error(f"{problem}: the value {value!r} is ignored")
                continue
            var.setter(value)

    @_never_raises(_values_like(float("nan")))
    def get_real(self, vrs):
        return self.rt.get_real(vrs, lambda vrs: self._get(vrs, self._lsc_types["Real"], float, float("nan")))

    @_never_raises(_values_like(0))
    def get_integer(self, vrs):
        return self._get(vrs, self._lsc_types["Integer"], int, 0)

    @_never_raises(_values_like(False))
    def get_boolean(self, vrs):
        return self._get(vrs, self._lsc_types["Boolean"], bool, False)

    @_never_raises(_values_like(""))
    def get_string(self, vrs):
        return self._get(vrs, self._lsc_types["String"], str, "")

    @_never_raises(_nothing)
    def set_real(self, vrs, values):
        if self.rt is None or not self.rt.set_inputs(vrs, values):
            self._set(vrs, values, self._lsc_types["Real"])

    @_never_raises(_nothing)
    def set_integer(self, vrs, values):
        self._set(vrs, values, self._lsc_types["Integer"])

    @_never_raises(_nothing)
    def set_boolean(self, vrs, values):
        self._set(vrs, values, self._lsc_types["Boolean"])

    @_never_raises(_nothing)
    def set_string(self, vrs, values):
        self._set(vrs, values, self._lsc_types["String"])

    @_never_raises(_nothing)
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.rt.setup(start_time, stop_time)

    @_never_raises(_nothing)
    def enter_initialization_mode(self):
        self.rt.enter_initialization()

    @_never_raises(_nothing)
    def exit_initialization_mode(self):
        self.rt.initialize()

    @_never_raises(lambda self, *args: False)
    def do_step(self, current_time, step_size):
        return self.rt.step(current_time, step_size)

    @_never_raises(_nothing)
    def terminate(self):
        self.rt.terminate()

    @_never_raises(lambda self: {"_lsc_invalid": "the FMU could not take its state"})
    def _get_fmu_state(self):
        return self.rt.get_state()

    @_never_raises(_nothing)
    def _set_fmu_state(self, state):
        self.rt.set_state(state)

    # called on the class (no instance to log to): failures travel inside the state object
    # and are reported by _set_fmu_state
    @staticmethod
    def _fmu_state_to_bytes(state):
        try:
            return json.dumps(state).encode("utf-8")
        except Exception as exc:
            return json.dumps({"_lsc_invalid": f"the state could not be serialized ({exc})"}).encode("utf-8")

    @staticmethod
    def _fmu_state_from_bytes(data):
        try:
            state = json.loads(bytes(data).decode("utf-8"))
        except Exception as exc:
            return {"_lsc_invalid": f"not a serialized state of this FMU ({type(exc).__name__}: {exc})"}
        return state if isinstance(state, dict) else {"_lsc_invalid": "not a serialized state of this FMU"}


def _make_slave_base():
    from pythonfmu import Boolean, Fmi2Slave, Integer, Real, String
    from pythonfmu.enums import Fmi2Status

    class LscSlave(_SafeMethods, Fmi2Slave):
        """Delegates to `LscRuntime` (``self.rt``, made by the subclass) and never raises."""

        _lsc_kinds = {Real: "Real", Integer: "Integer", Boolean: "Boolean", String: "String"}
        _lsc_types = {name: kind for kind, name in _lsc_kinds.items()}
        _lsc_error = Fmi2Status.error

    return LscSlave
