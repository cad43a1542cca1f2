"""One interface over fmpy's FMI 2.0 and FMI 3.0 Co-Simulation slaves, and the rules of FMI types.

The master calls an FMU through the names of fmpy's FMI 2.0 slave (``setupExperiment``,
``doStep``, ``getRealOutputDerivatives``, ``getFMUstate`` ...): `FMU3` gives an FMI 3.0 FMU the
same names, so that the numerics see one interface. What differs is said here:

- **Types.** Every variable is read and written with the getter and setter of its own FMI type
  (`access_type`): FMI 2.0 Real, Integer, Boolean, String (an Enumeration as Integer); FMI 3.0
  Float32, Float64, Int8 ... UInt64, Boolean, String, Binary (an Enumeration as Int64). The master
  groups them by *kind* (`KINDS`): Real, Integer, Boolean, String, Binary. An integer is checked
  against its type's range before it reaches ctypes (which would wrap 300 into an Int8 as 44); a
  finite value beyond a Float32's range is refused (ctypes would make it infinite), any other is
  rounded to the nearest Float32.
- **Start and steps.** FMI 3.0 has no ``fmi3SetupExperiment``: the start and stop time go to
  ``fmi3EnterInitializationMode``. The master instantiates without Event Mode (``eventModeUsed =
  false``: the FMU handles its events inside ``fmi3DoStep``) and without an intermediate update callback. ``fmi3DoStep`` reports what ``fmi2DoStep`` cannot; each of these ends the run with
  the reason: a request for Event Mode, a request to terminate, an early return the master did not allow.
- **Early return.** An FMU that declares ``mightReturnEarlyFromDoStep`` is instantiated with
  ``earlyReturnAllowed = true`` where the master can honour it (`_master.early_return_allowed`); its ``doStep``
  then returns the time ``lastSuccessfulTime`` it stopped at, before the end of the step (None when it
  reached the end), and the master re-plans the step to end there.
- **Derivatives.** FMI 3.0 Co-Simulation has ``fmi3GetOutputDerivatives`` (up to the description's
  ``maxOutputDerivativeOrder``) but no setter of input derivatives (its intermediate update mode
  replaces it): an FMI 3.0 FMU receives input values only.
"""


import numpy as np

from .._values import FMIValueError, fmi_value
_CLASSES = {}  # the slave classes and the refusal, created on first use (fmpy is imported late)

KINDS = {"Real": "Real", "Float64": "Real", "Float32": "Real",
         "Integer": "Integer", "Enumeration": "Integer", "Int8": "Integer", "UInt8": "Integer", "Int16": "Integer",
         "UInt16": "Integer", "Int32": "Integer", "UInt32": "Integer", "Int64": "Integer", "UInt64": "Integer",
         "Boolean": "Boolean", "String": "String", "Binary": "Binary", "Clock": "Clock"}

# what a result field holds for a variable of each FMI type (Float32 widens exactly into a double)
DTYPES = {"Real": np.float64, "Float64": np.float64, "Float32": np.float64, "UInt64": np.uint64,
          "Boolean": np.bool_, "String": object, "Binary": object}


def fmi3(md):
    """Whether a model description is FMI 3.0 (fmpy reads ``3.0``, ``3.0.1`` ...)."""
    return str(md.fmiVersion).startswith("3")


def access_type(variable, is_fmi3):
    """The FMI type whose getter and setter read and write ``variable``: its own, an Enumeration's as the
    standard says (FMI 2.0: Integer; FMI 3.0: Int64)."""
    if variable.type == "Enumeration":
        return "Int64" if is_fmi3 else "Integer"
    return variable.type


def kind(fmi_type):
    """The kind a type belongs to: Real, Integer, Boolean, String, Binary or Clock."""
    return KINDS[fmi_type]


def dtype(fmi_type):
    """The NumPy type of a result field holding a variable of the access type ``fmi_type``."""
    return DTYPES.get(fmi_type, np.int64 if KINDS.get(fmi_type) == "Integer" else object)


def convert(value, fmi_type, what):
    """``value`` as a value of the FMI type ``fmi_type`` (an access type, or FMI 2.0's Enumeration), or
    ValueError naming ``what``: the rules of `fmu_build._values.fmi_value`.

    An integer is never taken through a float beyond 2^53: a text is read as an integer, a float must be
    whole and at most 2^53 in magnitude; each is checked against its type's range. A Float32 is rounded
    to the nearest Float32 when set (a finite value beyond its range is refused here).

    Examples
    --------
    >>> convert("false", "Boolean", "x"), convert(1, "Boolean", "x"), convert("3", "Integer", "x")
    (False, True, 3)
    >>> convert("18446744073709551615", "UInt64", "u")
    18446744073709551615
    >>> convert(0.3, "Boolean", "b")
    Traceback (most recent call last):
    ...
    ValueError: b: a Boolean must be True/False, 1/0 or 'true'/'false'; found 0.3.
    >>> convert(300, "Int8", "i")
    Traceback (most recent call last):
    ...
    ValueError: i: an Int8 must be a whole number in [-128, 127]; found 300.
    """
    try:  # FMI 2.0's Enumeration is an Integer on the wire (FMI 3.0's is an Int64)
        return fmi_value(value, "Integer" if fmi_type == "Enumeration" else fmi_type)
    except FMIValueError as exc:
        raise ValueError(f"{what}: {exc}; found {value!r}.") from None


def is_refusal(exc):
    """Whether ``exc`` is a refusal of the master's (`refused`), whose text is the reason, not the FMU's log."""
    return type(exc) is _CLASSES.get("refused")


def refused(function, text):
    """An fmpy ``FMICallException`` of ``function`` saying ``text``: a value the master will not pass (out of
    its type's range, beyond a double or a Float32) or a step result it cannot take. The run stops there as
    on a failed FMI call."""
    cls = _CLASSES.get("refused")
    if cls is None:
        from fmpy.fmi1 import FMICallException

        class ExchangeRefused(FMICallException):
            def __init__(self, function, text):
                Exception.__init__(self, text)
                self.function, self.status = function, 3

        cls = _CLASSES["refused"] = ExchangeRefused
    return cls(function, text)


def terminals(unzipdir):
    """``{terminal name: [member variable names]}`` of an extracted FMI 3.0 FMU's
    ``terminalsAndIcons/terminalsAndIcons.xml`` (nested terminals by their dotted path); empty without one.

    Terminals group variables for graphical connection tools; the master connects variables, and a terminal
    named where a variable is expected is refused with its members (`_exchange.Component.variable`).
    """
    import os
    import xml.etree.ElementTree as ET

    path = os.path.join(unzipdir, "terminalsAndIcons", "terminalsAndIcons.xml")
    if not os.path.isfile(path):
        return {}
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError:  # a graphical annotation the master does not need; the variables are in the description
        return {}
    found = {}

    def walk(element, prefix):
        for t in element.findall("Terminal"):
            name = prefix + (t.get("name") or "")
            found[name] = [m.get("variableName") for m in t.findall("TerminalMemberVariable") if m.get("variableName")]
            walk(t, name + ".")

    walk(root.find("Terminals") if root.find("Terminals") is not None else root, "")
    return found


def binary_folder(unzipdir, md):
    """The platform folder the FMU's shared library must be in: ``x86_64-linux`` (FMI 3.0), ``linux64``
    (FMI 2.0) on this machine; the path of the library, or None with the folders the FMU has."""
    import os

    from fmpy import platform, platform_tuple, sharedLibraryExtension

    folder = platform_tuple if fmi3(md) else platform
    library = os.path.join(unzipdir, "binaries", folder, md.coSimulation.modelIdentifier + sharedLibraryExtension)
    if os.path.isfile(library):
        return folder, library, None
    binaries = os.path.join(unzipdir, "binaries")
    found = sorted(os.listdir(binaries)) if os.path.isdir(binaries) else []
    return folder, None, found


def provides_directional_derivatives(md, unzipdir):
    """Whether a Co-Simulation FMU declares directional derivatives: FMI 2.0 ``providesDirectionalDerivative``
    (read by fmpy), FMI 3.0 ``providesDirectionalDerivatives`` (read here: fmpy keeps only the FMI 2.0 name)."""
    if not fmi3(md):
        return bool(md.coSimulation.providesDirectionalDerivative)
    import os
    import xml.etree.ElementTree as ET

    try:
        cs = ET.parse(os.path.join(unzipdir, "modelDescription.xml")).getroot().find("CoSimulation")
    except (OSError, ET.ParseError):
        return False
    return cs is not None and cs.get("providesDirectionalDerivatives") in ("true", "1")


def slave_class(is_fmi3):
    """fmpy's FMI 2.0 or FMI 3.0 Co-Simulation slave class, with the master's interface."""
    return _fmu3_class() if is_fmi3 else _fmu2_class()


def _fmu2_class():
    if "2" not in _CLASSES:
        from fmpy.fmi2 import FMU2Slave

        class FMU2(FMU2Slave):  # (fmpy picks the FMI version's functions by the name's prefix)
            """fmpy's FMI 2.0 slave; ``prefix`` names its functions in messages."""

            prefix = "fmi2"

            def start(self, callbacks, logger, early_return=False):
                self.instantiate(callbacks=callbacks, loggingOn=True)

        _CLASSES["2"] = FMU2
    return _CLASSES["2"]


def _fmu3_class():
    if "3" not in _CLASSES:
        from fmpy.fmi3 import FMU3Slave

        class FMU3(FMU3Slave):
            """fmpy's FMI 3.0 Co-Simulation slave under the names of the FMI 2.0 one (see the module)."""

            prefix = "fmi3"
            start_time, stop_time, early_return = 0.0, None, False

            def start(self, callbacks, logger, early_return=False):
                """``fmi3InstantiateCoSimulation`` without Event Mode or intermediate update, with early return
                if ``early_return`` (the master can honour it); ``logger(status, message)`` receives the FMU's
                messages."""
                self.early_return = bool(early_return)
                self.instantiate(loggingOn=True, eventModeUsed=False, earlyReturnAllowed=self.early_return,
                                 requiredIntermediateVariables=None, intermediateUpdate=None,
                                 logMessage=lambda env, status, category, message: logger(status, message))

            def setupExperiment(self, startTime=0.0, stopTime=None, tolerance=None):
                self.start_time, self.stop_time = startTime, stopTime

            def enterInitializationMode(self):
                super().enterInitializationMode(tolerance=None, startTime=self.start_time, stopTime=self.stop_time)

            def doStep(self, currentCommunicationPoint, communicationStepSize, noSetFMUStatePriorToCurrentPoint=True):
                event, terminate, early, last = super().doStep(currentCommunicationPoint, communicationStepSize,
                                                               noSetFMUStatePriorToCurrentPoint)
                t, end = currentCommunicationPoint, currentCommunicationPoint + communicationStepSize
                if event:
                    raise refused("fmi3DoStep", f"the step from t = {t!r} set eventHandlingNeeded: the FMU asks for "
                                  "Event Mode, which this master does not run (instantiated with eventModeUsed = "
                                  "false, where the FMU must handle its events itself)")
                if terminate:
                    raise refused("fmi3DoStep", f"the FMU asked to terminate the simulation (terminateSimulation) in "
                                  f"the step from t = {t!r}, at t = {last!r}")
                # an FMU that reports the step's end (or beyond it within rounding) has reached it: a flag raised
                # for an event at the end of the step is no early return. Any time before the end is where the FMU
                # is, however close: its next step must start there (from the end it would be desynchronised)
                rounding = 1e-12 * max(abs(end), communicationStepSize)
                if not early:
                    return None
                if not t <= last <= end + rounding:  # a time outside the step cannot be a communication point of it
                    exc = refused("fmi3DoStep", f"the FMU returned early from the step from t = {t!r} to {end!r} "
                                  f"with lastSuccessfulTime = {last!r}, outside the step")
                    exc.beyond = last > end
                    raise exc
                if last >= end:
                    return None
                if not self.early_return:
                    raise refused("fmi3DoStep", f"the FMU returned early from the step from t = {t!r} (at t = "
                                  f"{last!r}, before t = {end!r}) although earlyReturnAllowed is false")
                return last  # the time the FMU reached: the master re-plans the step to end there

            def getRealOutputDerivatives(self, vr, order):
                return self.getOutputDerivatives(vr, order)

            def setRealInputDerivatives(self, vr, order, value):
                raise refused("setRealInputDerivatives", "FMI 3.0 Co-Simulation has no setter of input derivatives")

            def getFMUstate(self):
                return self.getFMUState()

            def setFMUstate(self, state):
                self.setFMUState(state)

            def freeFMUstate(self, state):
                self.freeFMUState(state)

        _CLASSES["3"] = FMU3
    return _CLASSES["3"]
