"""What runs inside a pythonfmu FMU (the package is copied into it, next to a private copy of lsc).

The slave class generated for a model delegates everything to `LscRuntime`.
Design rules, from pythonfmu's behaviour:

- A Python exception in any FMI call is fatal for the instance (pythonfmu
  destroys it). So a bad value set by a master never raises: it is logged
  as an error, the last valid value stays in effect, and every following
  ``do_step`` returns False (fmi2Discard) with the reason logged, until a
  valid value is set. No step ever runs on a bad value.
- The completion is rebuilt only when something it depends on changed
  (``lambda``, ``method`` or a parameter); otherwise it is reused.
- Constant coefficients A, B are stepped exactly by default (`_ExactStepper`:
  the matrix exponential of lsc.ExactPropagator, once per step size; the
  inputs' extrapolation polynomials are polynomial forcing, stepped exactly).
  Time-varying completions can take a fourth-order Magnus step with one
  evaluation of the completion per communication step (``solver = 5``).
- Otherwise one ODE solver runs across communication steps; a step end is read from
  the solver's dense output, so a communication step costs a few Python
  calls, not a fresh integration. The solver restarts from the current
  state when anything it depends on changes (``lambda``, ``method``, a
  parameter, ``solver``, tolerances, the time given by the master) and
  when a snapshot is taken or restored.
- The FMU state snapshot holds everything the next step depends on: time,
  the continuous state, every variable value and the pending errors; since
  taking a snapshot restarts the solver there, a master can roll back and
  repeat a step bit for bit. A state to restore is checked first (its model,
  its length, finite numbers); a bad one is refused and leaves a pending error.
- pythonfmu 0.7.0 turns any exception escaping a Python FMI method into
  fmi2Fatal and then frees the slave object the C++ layer still points to:
  the host crashed at its next call. `LscSlave` therefore implements every
  FMI method itself and never lets an exception out. Its only statuses are
  the ones pythonfmu can return without an exception: fmi2OK, and fmi2Discard
  from doStep. A refused call logs an fmi2Error message and changes nothing.
- The FMI 2.0 Co-Simulation call sequence and the variability rules are
  enforced: doStep only between exitInitializationMode and terminate,
  setupExperiment only before enterInitializationMode, fixed parameters only
  before exitInitializationMode, nothing set after terminate, and doStep only
  from the FMU's own time with a finite, non-negative step.

The rooms: `_core` (`LscRuntime`: variables, values, the completion), `_calls`
(the FMI call sequence), `_stepping` (doStep: exact, Magnus or a scipy
solver), `_steppers` and `_interpolant` (the steppers themselves),
`_inputs` (input signals and their derivatives), `_snapshot` (FMU states),
`_variables` (the FMU's own variables), `_slave` (the FMI guard: no
exception reaches pythonfmu) and `_loader` (pythonfmu 0.7.0 workarounds).
`_lsc` imports lsc and the ODE solvers, from the FMU's private copies when
there are ones.
"""

from ._core import LscRuntime
from ._loader import give_back_loader_reference, release_loader_state_at_exit
from ._slave import make_slave_base
from ._variables import start_name

__all__ = ["LscRuntime", "give_back_loader_reference", "make_slave_base", "release_loader_state_at_exit", "start_name"]
