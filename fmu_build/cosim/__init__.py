"""A co-simulation master for FMI 2.0 and FMI 3.0 Co-Simulation FMUs (fmpy's low-level API).

The master couples FMUs by their connections, at a fixed or controlled macro step ``H``:

- **The system** (:func:`read_system`) is validated before anything runs:
  unique component names that are plain identifiers (never paths), one source
  per input, causality and type agreement, FMUs inside a packed archive
  (unless ``allow_external=True``), a size limit on everything unpacked, and
  every temporary folder removed on every exit path.
- **Types**: Real (FMI 3.0: Float32, Float64), Integer (FMI 3.0: Int8 ...
  UInt64; Enumeration too) and Boolean connections are exchanged with the
  getter and setter of each variable's own type (FMI 2.0 value references
  are unique per type only); ``output`` and ``start_values`` may name any
  type (String, Binary too); a value that cannot be read as the variable's
  type, or is outside its range, is refused. FMI 3.0 specifics (no Event
  Mode, early return or input derivatives; clocks, arrays and terminals
  refused) are in ``_fmi``.
- **Ordering**: ``"jacobi"`` steps every FMU from the values of the last
  communication point; ``"gauss-seidel"`` steps them one after the other in
  the order of the connection graph (sources first; inside a cycle, the order
  the system lists them), each using what the ones before it already computed.
- **Inputs over a step**: the value of a connected output is known at the
  communication points (and, from an FMU that declares
  ``maxOutputDerivativeOrder``, its derivatives there). With
  ``extrapolation = p`` the input over the step is the degree-``p``
  polynomial through the last ``p + 1`` values (Gauss-Seidel: including the
  newest one), its derivatives replaced by the exact ones where the source
  provides them. An FMU that declares ``canInterpolateInputs`` receives every
  derivative order the master has: the polynomial's 1..p, then the source's
  exact derivatives beyond ``p`` (up to the highest order the FMU accepts,
  probed once with rollback); orders the master does not have are not sent.
- **Algebraic loops**: a cycle of direct feedthrough is reported and solved
  as a fixed point (Anderson acceleration, to the tolerance, its gain
  measured; module ``_loops``); with ``iterations = 0`` it is then cut and a
  gain of magnitude 1 or more ends the run, with ``iterations > 0`` it is
  solved at every exchange.
- **Step iteration**: with ``iterations > 0`` every macro step is repeated
  (rollback) with the inputs interpolated through the end values just
  computed (at ``p = 0`` the line through the start and end values, for the
  FMUs that interpolate their inputs; the end value held, first order, for
  the others), until the coupling values change by less than the tolerance.
- **Output derivatives** are used while they are Taylor coefficients of the
  values produced (module ``_derivatives``).
- **Step control**: ``step_control=True`` varies ``H`` to keep the defect of
  what each step produced within ``atol + rtol |y|``, locating jumps
  (module ``_stepper``).
- **Divergence is never success, growth is not divergence**: a non-finite
  coupling value, or a value on a cycle of the connection graph that leaves
  its extrapolation by more than its size while swinging and growing, ends
  the run with ``success=False`` and a message naming the variable, the time
  and the recommended configuration (module ``_divergence``).
- A failing FMI call or a value an FMU rejects stops the run: the result
  keeps the rows computed so far, ``success`` is False and ``message`` names
  the component, the variable and the time.
"""

from ._graph import _component_order, _graph, _weights
from ._master import ALGORITHMS, cosimulate
from ._result import AlgebraicLoopWarning, CosimResult, _Progress
from ._system import System, read_system

__all__ = ["cosimulate", "CosimResult", "read_system", "System", "AlgebraicLoopWarning"]
