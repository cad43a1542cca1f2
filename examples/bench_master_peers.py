"""Co-simulation masters side by side: our step control against libcosim's ECCO, OMSimulator's
oms-mav and oms-mav2, and MasterSim's step doubling, on shared scenarios.

For every scenario and master the script counts macro steps, rejected steps and FMU calls
(``fmi2DoStep``, summed over the FMUs, rolled-back attempts included) against the error to a
monolithic solution, and reports the FMU calls each master needs at an error of 1e-6 (interpolated
between its runs in log-log, extrapolated by its observed order where no run gets there).

Scenarios
---------
``chain``
    A mass-spring-damper chain split into three FMUs through force/velocity connections (two power
    bonds): ``A`` (mass 1 on a wall spring) and ``C`` (mass 3 on a wall spring) send their velocity
    and receive a force; ``B`` (mass 2 and the two coupling spring-dampers) receives both velocities
    and returns both forces (direct feedthrough through the dampers). The FMUs are generated in C here
    (``examples/plants/lti.c``: exact steps for the received input polynomial, output derivatives,
    rollback, an ``nDoStep`` counter). Reference: the monolithic 6-state ODE by a matrix exponential.
``chain-values``
    The same chain with FMUs that give no output derivatives and do not interpolate their inputs:
    every master then holds the inputs over a step.
``loop``
    The loop through a differentiated input of docs/cosimulation.md: the C lag ``w' = -w + g x2``
    feeds the index-2 follower ``x1' + x2 = 0, x1 = w`` (a native DAE FMU, alternative completion);
    ``x2`` goes back to the lag (``g = 0.2``). The bond: ``w`` times ``x2``. Exact solution.
``path``
    A DAE FMU driven by a plant: the prescribed-path controller (index 3, native, alternative
    completion, ``lambda = 10``) of examples/ssp/path_control.toml sends the force ``F`` to the C
    mass-spring-damper, which returns its position and velocity. The bond: ``F`` times the velocity.
    Reference: the DAE and the plant as one index-3 DAE solved by lsc (DOP853, rtol 1e-13).

Masters
-------
``ours``
    ``fmu_build.cosimulate``, fixed step and ``step_control=True`` at several ``rtol``.
``ECCO``
    libcosim's ECCO (libcosimpy ``CosimAlgorithm.create_ecco_algorithm``, in a subprocess): Jacobi with
    zero-order hold, every FMU stepped once per macro step, a PI controller on the energy residual of
    the power bonds after each step, no rollback.
``oms-mav``, ``oms-mav2``, ``MasterSim``
    Re-implementations of OMSimulator's two adaptive masters (``SystemWC::doStep``) and of MasterSim's
    step doubling (``MasterSim::doErrorCheckRichardson``) as small controller classes below, driving our
    master's FMU layer (its exchange, rollback and result; zero-order hold as those masters do).

Errors are ``max |y - y*| / max |y*|`` over the communication points and the listed outputs, against
the monolithic solution. Every setting is stated in the report.

Run: ``python examples/bench_master_peers.py [--full | --quick] [--only SCENARIO] [--out DIR] [--docs]``.
The default runs every scenario at two or three settings per master (a few minutes on two cores);
``--full`` at the settings listed in each scenario (down to tolerances where the zero-order-hold
masters take hundreds of thousands of steps: tens of minutes); ``--quick`` the chain only on [0, 2],
one run per master (the test's case). ``--docs``: the report and figure to
docs/_generated/bench_master_peers.* instead of out/. libcosimpy (``pip install -e ".[cosim]"``) and gcc are needed.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.linalg import expm  # noqa: E402

HERE = Path(__file__).resolve().parent
for _folder in (HERE, HERE / "plants"):
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))
from _docs_output import HELP, ROOT, output_path  # noqa: E402

import plants  # noqa: E402

TARGET = 1e-6  # the error at which the FMU calls are compared

# -- the chain: masses 1, 2, 3 on springs k0 (wall), k1, k2, k3 (wall) with dampers c0 ... c3 ---------------------
MASSES = (1.0, 0.5, 1.0)
SPRINGS = (4.0, 10.0, 6.0, 2.0)
DAMPERS = (0.1, 0.3, 0.2, 0.05)
CHAIN_X0 = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # x1, v1, x2, v2, x3, v3: mass 1 displaced by 1


def chain_matrix():
    """The monolithic chain ``z' = M z``, ``z = (x1, v1, x2, v2, x3, v3)``."""
    (m1, m2, m3), (k0, k1, k2, k3), (c0, c1, c2, c3) = MASSES, SPRINGS, DAMPERS
    M = np.zeros((6, 6))
    M[0, 1] = M[2, 3] = M[4, 5] = 1.0
    M[1] = np.array([-k0 - k1, -c0 - c1, k1, c1, 0.0, 0.0]) / m1
    M[3] = np.array([k1, c1, -k1 - k2, -c1 - c2, k2, c2]) / m2
    M[5] = np.array([0.0, 0.0, k2, c2, -k2 - k3, -c2 - c3]) / m3
    return M


def chain_reference(t):
    """``(v1, v3)`` of the monolithic chain at the times ``t`` (matrix exponential)."""
    M, z0 = chain_matrix(), np.array(CHAIN_X0)
    Z = np.array([expm(M * s) @ z0 for s in np.asarray(t, dtype=float)])
    return np.array([Z[:, 1], Z[:, 5]])


def build_chain(dest, derivatives):
    """The three chain FMUs in ``dest`` (with or without output derivatives and input interpolation)."""
    (m1, m2, m3), (k0, k1, k2, k3), (c0, c1, c2, c3) = MASSES, SPRINGS, DAMPERS
    kw = {"derivatives": derivatives, "interpolate": derivatives}
    suffix = "" if derivatives else "Values"
    a = plants.build_lti(dest, f"MassA{suffix}", [[0, 1], [-k0 / m1, -c0 / m1]], [[0], [1 / m1]], [[0, 1]], [[0]],
                         CHAIN_X0[:2], ["F"], ["v"], description="mass 1 on a wall spring: force in, velocity out",
                         **kw)
    # B's states: d1 = x1 - x2, d2 = x2 - x3, v2; its outputs: the forces on mass 1 and on mass 3
    b = plants.build_lti(dest, f"Spring{suffix}", [[0, 0, -1], [0, 0, 1], [k1 / m2, -k2 / m2, -(c1 + c2) / m2]],
                         [[1, 0], [0, -1], [c1 / m2, c2 / m2]], [[-k1, 0, c1], [0, k2, c2]], [[-c1, 0], [0, -c2]],
                         [CHAIN_X0[0] - CHAIN_X0[2], CHAIN_X0[2] - CHAIN_X0[4], CHAIN_X0[3]], ["v1", "v3"],
                         ["F1", "F3"], description="mass 2 between two spring-dampers: velocities in, forces out",
                         **kw)
    c = plants.build_lti(dest, f"MassC{suffix}", [[0, 1], [-k3 / m3, -c3 / m3]], [[0], [1 / m3]], [[0, 1]], [[0]],
                         CHAIN_X0[4:], ["F"], ["v"], description="mass 3 on a wall spring: force in, velocity out",
                         **kw)
    return {"components": {"A": str(a), "B": str(b), "C": str(c)},
            "connections": [("A.v", "B.v1"), ("B.F1", "A.F"), ("C.v", "B.v3"), ("B.F3", "C.F")]}


def build_loop(dest):
    import scenarios

    scenarios.build_loop_system(dest, g=LOOP_GAIN, plant="c", dae="native")
    return {"components": {"dae": str(Path(dest) / "fmus" / "Follower.fmu"),
                           "plant": str(Path(dest) / "fmus" / "Lag.fmu")},
            "connections": [("plant.w", "dae.w"), ("dae.x2", "plant.u")]}


def build_path(dest):
    import scenarios

    scenarios.build_path_system(dest, method="alternative", lam=10.0, target="native")
    return {"components": {"dae": str(Path(dest) / "fmus" / "PathControl.fmu"),
                           "plant": str(Path(dest) / "fmus" / "MSD.fmu")},
            "connections": [("plant.x", "dae.ym"), ("plant.v", "dae.vm"), ("dae.F", "plant.F")]}


LOOP_GAIN = 0.2


def loop_reference(t):
    import scenarios

    w, _, x2 = scenarios.loop_reference(np.asarray(t, dtype=float), LOOP_GAIN)
    return np.array([w, x2])


def path_reference(t):
    import scenarios

    return scenarios.path_reference(np.asarray(t, dtype=float))[3:5]


class Scenario:
    """A system, its monolithic reference and the settings every master runs it with.

    ``bonds``: ECCO's power bonds ``(output a, input a, output b, input b)`` (the product of an FMU's output
    and input is the power it exchanges); ``ours``: our master's options, ``control`` the ``rtol`` of its
    controlled runs, ``fixed`` the steps of its fixed-step runs; ``ecco``: ECCO's tolerances; ``zoh``: the
    tolerances of the zero-order-hold peers (oms-mav, oms-mav2, MasterSim).
    """

    def __init__(self, name, title, build, reference, outputs, bonds, stop_time, h0, max_step, ours, control, fixed,
                 ecco, zoh, start_values=None, quick=None, default=None):
        self.name, self.title, self.build, self.reference = name, title, build, reference
        self.outputs, self.bonds, self.stop_time, self.h0, self.max_step = outputs, bonds, stop_time, h0, max_step
        self.ours, self.control, self.fixed, self.ecco, self.zoh = ours, control, fixed, ecco, zoh
        self.start_values = dict(start_values or {})
        self.sizes = {"quick": quick or {}, "default": default or {}, "full": {}}
        t = np.linspace(0.0, stop_time, 2001)
        self._amplitude = None
        self._grid = t

    def settings(self, key, size):
        """The settings ``key`` (``"control"``, ``"fixed"``, ``"ecco"``, ``"zoh"``) of a run of this ``size``."""
        return self.sizes[size].get(key, getattr(self, key))

    @property
    def amplitude(self):
        if self._amplitude is None:
            self._amplitude = np.max(np.abs(self.reference(self._grid)), axis=1)
        return self._amplitude

    def error(self, t, Y):
        """``max |y - y*| / max |y*|`` over the times ``t`` and the outputs (rows of ``Y``); inf if not finite."""
        t, Y = np.asarray(t, dtype=float), np.asarray(Y, dtype=float)
        if Y.size == 0 or not np.all(np.isfinite(Y)):
            return math.inf
        # the references integrate from t = 0: evaluated on a grid that starts there
        reference = self.reference(np.concatenate([[0.0], t]))[:, 1:] if t[0] > 0 else self.reference(t)
        return float(np.max(np.abs(Y - reference) / self.amplitude[:, None]))


SCENARIOS = {
    "chain": Scenario(
        "chain", "mass-spring-damper chain in three FMUs (exact C FMUs with output derivatives)",
        lambda dest: build_chain(dest, True), chain_reference, ["A.v", "C.v"],
        [("A.v", "A.F", "B.F1", "B.v1"), ("C.v", "C.F", "B.F3", "B.v3")], 10.0, 0.01, 0.5,
        {"extrapolation": 2}, [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8], [0.04, 0.02, 0.01, 0.005],
        [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8], [1e-1, 1e-2, 1e-3],
        quick={"stop_time": 2.0, "control": [1e-5], "fixed": [0.01], "ecco": [1e-4], "zoh": [1e-2]},
        default={"control": [1e-4, 1e-6, 1e-8], "fixed": [0.02, 0.005], "ecco": [1e-3, 1e-5, 1e-7]}),
    "chain-values": Scenario(
        "chain-values", "the same chain, FMUs without output derivatives or input interpolation",
        lambda dest: build_chain(dest, False), chain_reference, ["A.v", "C.v"],
        [("A.v", "A.F", "B.F1", "B.v1"), ("C.v", "C.F", "B.F3", "B.v3")], 10.0, 0.01, 0.5,
        {"extrapolation": 0}, [1e-1, 1e-2, 1e-3], [0.01, 0.001, 0.0001],
        [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8], [1e-1, 1e-2, 1e-3],
        default={"fixed": [0.01, 0.001], "ecco": [1e-3, 1e-5, 1e-7]}),
    "loop": Scenario(
        "loop", f"loop through a differentiated input (C lag, native follower, g = {LOOP_GAIN})",
        build_loop, loop_reference, ["plant.w", "dae.x2"], [("plant.w", "plant.u", "dae.x2", "dae.w")], 2.0, 0.01,
        0.5, {"algorithm": "jacobi", "extrapolation": 2, "lambda_per_step": 1.0},
        [1e-3, 1e-4, 1e-5, 1e-6, 1e-7], [0.04, 0.02, 0.01, 0.005], [1e-3, 1e-5, 1e-7], [1e-1, 1e-2, 1e-3],
        start_values={"plant.substeps": 200.0},
        default={"control": [1e-3, 1e-5, 1e-7], "fixed": [0.04, 0.01]}),
    "path": Scenario(
        "path", "prescribed-path DAE FMU (index 3, native) driving a C mass-spring-damper",
        build_path, path_reference, ["plant.x", "plant.v"], [("plant.v", "plant.F", "dae.F", "dae.vm")], 10.0,
        0.01, 0.5, {"extrapolation": 2}, [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8], [0.04, 0.02, 0.01, 0.005],
        [1e-3, 1e-4, 1e-5, 1e-6, 1e-7], [1e-1, 1e-2, 1e-3], start_values={"plant.substeps": 200.0},
        default={"control": [1e-4, 1e-6, 1e-8], "fixed": [0.04, 0.01], "ecco": [1e-3, 1e-5, 1e-7]}),
}

# ECCO's settings: libcosim's own ECCO test (tests/ecco_algorithm_test.cpp: safety 0.99, change rate 0.2 ... 1.5,
# PI gains 0.2 and 0.15) with abs_tolerance = rel_tolerance = tol, and the defaults of libcosimpy's EccoParams
# with its first step (ECCO keeps the first two steps at that size and can repeat none: a first step of 0.01 leaves a
# start-up error of 1e-3 on the chain that no later step removes)
ECCO_TEST = {"safety_factor": 0.99, "step_size": 1e-4, "min_step_size": 1e-6, "min_change_rate": 0.2,
             "max_change_rate": 1.5, "p_gain": 0.2, "i_gain": 0.15}
ECCO_DEFAULTS = {"safety_factor": 0.8, "step_size": 0.01, "min_step_size": 1e-4, "max_step_size": 0.1,
                 "min_change_rate": 0.01, "max_change_rate": 0.2, "abs_tolerance": 1e-4, "rel_tolerance": 1e-4,
                 "p_gain": 0.2, "i_gain": 0.15}
# the peers that no package registry installs: re-implemented from their sources (the classes below)
NOT_INSTALLABLE = {
    "OMSimulator (oms-mav, oms-mav2)": "its PyPI package is a source archive that downloads the OMSimulator binaries "
                                       "from the OpenModelica build server while it installs (no wheel on PyPI)",
    "MasterSim": "a C++ application with no package on PyPI",
}
ECCO_MISSING = "ECCO not run: libcosimpy is not installed (pip install -e \".[cosim]\")"
KEEP_TRAJECTORIES = False  # rows keep the time and outputs of their run (set by --quick)
PEER_MIN_STEP = 1e-8  # min_step of the re-implemented peers
PEER_BUDGET = 400_000  # attempts a peer run may take (a zero-order hold at a tight tolerance needs millions)
ECCO_BUDGET = 400_000  # macro steps an ECCO run may take


# -- counting FMU calls ---------------------------------------------------------------------------------------------
@contextlib.contextmanager
def counted_do_steps():
    """Count every ``fmi2DoStep`` made through fmpy in this process (our master and the peers on its FMU layer)."""
    from fmpy.fmi2 import FMU2Slave

    count = [0]
    original = FMU2Slave.doStep

    def doStep(self, *args, **kwargs):  # noqa: N802 (fmpy's name)
        count[0] += 1
        return original(self, *args, **kwargs)

    FMU2Slave.doStep = doStep
    try:
        yield count
    finally:
        FMU2Slave.doStep = original


# -- the re-implemented peers, on our master's FMU layer -----------------------------------------------------------
class Peer:
    """A peer's macro-step control driving one run of our master (``fmu_build.cosim._run.Run``).

    It is put in place of the master's own controller (``driven_by``), so the peer steps, rolls back and
    exchanges through the same FMU calls as the master, and the result (rows, ``steps``, ``rejected``,
    ``success``) is assembled the same way. A subclass implements ``advance(t0, stop_time, H, progress)``;
    the run's ``rtol``, ``atol``, ``min_step`` and ``max_step`` are the peer's tolerances and bounds.
    """

    def __init__(self, run):
        self.run, self.control = run, run.control
        self.attempts = 0

    def step(self, t, H, read_only=False):
        """Every FMU steps from ``t`` over ``H`` with its inputs held (zero-order hold); the outputs at ``t + H``
        are read (``read_only``: before any input is set, as a master that reads, then decides, then sets)."""
        from fmu_build.cosim._result import _Stop

        self.attempts += 1
        if self.attempts > PEER_BUDGET:
            raise _Stop(f"{type(self).__name__}: more than {PEER_BUDGET} attempts by t = {t!r}")
        run = self.run
        run.check_time(t, H)
        ordered = run.exchange_needed
        run.exchange_needed = ordered and not read_only
        try:
            return run.step_all(t, H)
        finally:
            run.exchange_needed = ordered

    def keep(self, t, H, band, t_new=None, update=True):
        """The step to ``t_new`` (default ``t + H``) is taken: a result row; with ``update`` the inputs that feed
        outputs directly are set from the new outputs and those outputs read again (else the next step's inputs
        take the outputs as read after the step)."""
        run = self.run
        if update and run.exchange_needed:
            run.loops.exchange(None, t + H)
        run.accept(t + H if t_new is None else t_new, H, run.measure(band, t, H))


class OmsMav(Peer):
    """OMSimulator's ``oms-mav`` (``SystemWC::doStep``, ``solverMethod == oms_solver_wc_mav``).

    Every FMU steps from ``t`` to ``t + H`` with its inputs held; the error of each connection is
    ``|u - y(t + H)| / (rtol |y(t + H)| + rtol)``, ``u`` the input's value over the step (the output at
    ``t``, set at the last communication point) and ``y(t + H)`` the output read after the step, before
    the inputs are updated (OMSimulator's absolute tolerance is its relative one: ``atol`` is not used).
    With ``e`` the largest, ``r = (1 / e)^(1/2)``: ``r < 1`` and ``H > min_step`` roll the step back and
    repeat it with ``H max(0.5, 0.9 r)``; otherwise it is kept and the next step is ``H 0.9 r``, the
    factor capped at 1.5 when above 1 (no lower bound: a step kept at ``min_step`` shrinks further and is
    clamped to ``min_step`` before the next attempt). One ``fmi2DoStep`` per FMU per attempt.
    """

    SAFETY, MAX_CHANGE, MIN_CHANGE = 0.9, 1.5, 0.5

    def error(self, t, H, held):
        band = self.step(t, H, read_only=True)
        y = self.run.coupling.value
        rtol = self.control.rtol
        return band, np.abs(held - y) / (np.abs(y) * rtol + rtol)

    def advance(self, t0, stop_time, H, progress):
        run, control, t = self.run, self.control, t0
        while t < stop_time:
            H = min(max(H, control.min_step), control.max_step)
            t_next = t + H
            if t_next > stop_time:
                t_next, H = stop_time, stop_time - t
            held = run.coupling.value.copy()
            snap = run.save(t)
            band, scaled = self.error(t, H, held)
            worst = float(np.max(scaled, initial=0.0))
            ratio = math.inf if worst == 0.0 else (1.0 / worst) ** 0.5
            if ratio < 1.0 and control.min_step < H:
                run.restore(snap, t)
                run.release(snap)
                run.rejected += 1
                H *= max(ratio * self.SAFETY, self.MIN_CHANGE)
                continue
            run.release(snap)
            self.keep(t, H, band, t_new=t_next)
            t = t_next
            ratio *= self.SAFETY
            if ratio > 1.0:
                ratio = min(ratio, self.MAX_CHANGE)
            H *= ratio
            progress.update(t - t0)


class OmsMav2(OmsMav):
    """OMSimulator's ``oms-mav2`` ("double step"), as its source does it (OMSimulator 2940ef1, unchanged since
    the method was added in 2019): the FMUs step from ``t`` to ``t + H`` (pass 0), the outputs ``y0`` are read,
    the states rolled back, the same step taken again (pass 1: the same inputs, so the same result), the
    inputs updated from the new outputs, and a third pass does nothing (each FMU is already at ``t + H``).
    The error of a connection is ``|y1 - y0| / (rtol |y0| + rtol)``, ``y1`` its output after the inputs were
    updated: nonzero only for outputs that depend on an input directly. Step-size rule as ``oms-mav``; two
    ``fmi2DoStep`` per FMU per attempt.
    """

    def error(self, t, H, held):
        run = self.run
        snap = run.save(t)
        self.step(t, H, read_only=True)
        before = run.coupling.value.copy()
        run.restore(snap, t)
        run.release(snap)
        band = self.step(t, H, read_only=True)
        if run.exchange_needed:  # OMSimulator's updateInputs: an output with feedthrough moves
            run.loops.exchange(None, t + H)
        rtol = self.control.rtol
        return band, np.abs(run.coupling.value - before) / (np.abs(before) * rtol + rtol)


class MasterSimDoubling(Peer):
    """MasterSim's step doubling (``MasterSim::doStep`` and ``doErrorCheckRichardson``, error control mode
    ``ADAPT_STEP``), on its default Gauss-Seidel algorithm without iteration.

    A step of ``h`` from ``t`` gives ``y_full``; the FMUs are rolled back and take two steps of ``h/2``
    (the second from the values of the first, ``y_mid``), giving ``y_half``. With weights
    ``w = |y_half| rtol + atol`` over the connected outputs, the error is the larger of the root mean
    squares of ``(y_half - y_full) / w`` and of ``(h/2) ((y_full - y(t)) / h - (y_full - y_mid) / (h/2)) / w``.
    Above 1 (and ``h > min_step``) the step is rolled back and repeated with ``h s``,
    ``s = min(2, max(0.2, 0.9 / err^(1/2)))``; else the two half steps are kept and the next step is
    ``min(h s, max_step)``. Three ``fmi2DoStep`` per FMU per attempt.
    """

    def advance(self, t0, stop_time, H, progress):
        run, control, t = self.run, self.control, t0
        proposed = H
        while t < stop_time:
            h = proposed
            if t + h + 1e-10 > stop_time:
                h = stop_time - t
            y_t = run.coupling.value.copy()
            snap = run.save(t)
            while True:
                # MasterSim reads each FMU's outputs right after its step (syncSlaveOutputs) and sets the next
                # step's inputs from those values
                self.step(t, h, read_only=True)
                y_full = run.coupling.value.copy()
                run.restore(snap, t)
                half = 0.5 * h
                self.step(t, half, read_only=True)
                y_mid = run.coupling.value.copy()
                band = self.step(t + half, half, read_only=True)
                y_half = run.coupling.value
                w = np.abs(y_half) * control.rtol + control.atol
                err = float(np.sqrt(np.mean(((y_half - y_full) / w) ** 2)))
                slope = half * ((y_full - y_t) / h - (y_full - y_mid) / half)
                err = max(err, float(np.sqrt(np.mean((slope / w) ** 2))))
                scale = 2.0 if err == 0.0 else min(2.0, max(0.2, 0.9 / math.sqrt(err)))
                if err > 1.0:
                    if h > control.min_step:
                        run.rejected += 1
                        run.restore(snap, t)
                        h = max(h * scale, control.min_step)
                        continue
                    proposed = h
                else:
                    proposed = min(h * scale, control.max_step)
                break
            run.release(snap)
            t_new = stop_time if h == stop_time - t else t + h
            self.keep(t, h, band, t_new=t_new, update=False)
            t = t_new
            if t + proposed > stop_time or t + proposed > stop_time * 0.999999:
                proposed = stop_time - t
            progress.update(t - t0)


PEERS = {"oms-mav": (OmsMav, "jacobi"), "oms-mav2": (OmsMav2, "jacobi"),
         "MasterSim": (MasterSimDoubling, "gauss-seidel")}


@contextlib.contextmanager
def driven_by(peer):
    """Our master's runs inside this block are driven by ``peer`` (a ``Peer`` subclass) instead of its controller."""
    from fmu_build.cosim import _run

    original = _run.Controller
    _run.Controller = peer
    try:
        yield
    finally:
        _run.Controller = original


# -- running the masters --------------------------------------------------------------------------------------------
def record(sc, master, setting, success, message, steps, rejected, calls, t, Y, **extra):
    err = sc.error(t, Y) if len(t) else math.inf
    row = {"scenario": sc.name, "stop_time": sc.stop_time, "master": master, "setting": setting,
           "success": bool(success), "message": str(message), "steps": int(steps), "rejected": int(rejected),
           "calls": int(calls), "error": err, **extra}
    if KEEP_TRAJECTORIES:  # the quick run keeps them (its test recomputes every error)
        row.update(t=[float(x) for x in t], Y=[[float(v) for v in y] for y in Y])
    status = "ok" if success else "FAILED: " + str(message)[:90]
    print(f"  {master:<9} {setting:<34} steps {steps:>8} rejected {rejected:>6} calls {calls:>9} error {err:9.2e}  "
          f"{status}", flush=True)
    return row


def run_cosimulate(sc, system, master, setting, peer=None, **options):
    from fmu_build import cosimulate

    options = {"start_values": sc.start_values, "output": sc.outputs, "progress": False, **options}
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught, counted_do_steps() as calls:
        warnings.simplefilter("always")
        with driven_by(peer) if peer is not None else contextlib.nullcontext():
            r = cosimulate(system, sc.stop_time, **options)
    notes = sorted({f"{w.category.__name__}: {str(w.message)[:160]}" for w in caught})
    return record(sc, master, setting, r.success, r.message, r.steps, r.rejected, calls[0], r["time"],
                  [r[o] for o in sc.outputs], seconds=time.perf_counter() - t0, warnings=notes)


def run_ours(sc, system, size):
    rows = []
    for rtol in sc.settings("control", size):
        rows.append(run_cosimulate(sc, system, "ours", f"step control, rtol = {rtol:g}", step_size=sc.h0,
                                   step_control=True, rtol=rtol, max_step=sc.max_step, **sc.ours))
    for H in sc.settings("fixed", size):
        rows.append(run_cosimulate(sc, system, "ours-fixed", f"H = {H:g}", step_size=H, **sc.ours))
    return rows


def run_peers(sc, system, size):
    rows = []
    for name, (peer, algorithm) in PEERS.items():
        for tol in sc.settings("zoh", size):
            atol = tol / 10 if name == "MasterSim" else tol  # MasterSim's defaults: relTol 1e-5, absTol 1e-6
            setting = f"rtol = {tol:g}" + (f", atol = {atol:g}" if name == "MasterSim" else "")
            rows.append(run_cosimulate(sc, system, name, setting, peer=peer, step_size=sc.h0, step_control=True,
                                       rtol=tol, atol=atol, min_step=PEER_MIN_STEP, max_step=sc.max_step,
                                       algorithm=algorithm, extrapolation=0))
    return rows


_ECCO = r'''
import json, sys, time
from libcosimpy.CosimAlgorithm import CosimAlgorithm, EccoParams
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave
log_output_level(CosimLogLevel.ERROR)
sc = json.load(sys.stdin)
for params in sc["runs"]:
    algorithm = CosimAlgorithm.create_ecco_algorithm(EccoParams(**params))
    ex = CosimExecution.from_algorithm(algorithm)
    index = {n: ex.add_local_slave(CosimLocalSlave(path, n)) for n, path in sc["components"].items()}
    refs = {n: {v.name.decode(): v.reference for v in ex.slave_variables(i)} for n, i in index.items()}
    def ref(name):
        comp, var = name.split(".", 1)
        return index[comp], refs[comp][var]
    for name, value in sc["start_values"].items():
        ex.real_initial_value(*ref(name), float(value))
    for a, b in sc["connections"]:
        if ex.connect_real_variables(*ref(a), *ref(b)) != 0:
            raise RuntimeError(f"libcosim refused the connection {a} -> {b}")
    for out_a, in_a, out_b, in_b in sc["bonds"]:
        (sa, oa), (sb, ob) = ref(out_a), ref(out_b)
        if algorithm.add_power_bond(sa, oa, ref(in_a)[1], sb, ob, ref(in_b)[1]) != 0:
            raise RuntimeError("libcosim refused a power bond")
    observer = CosimObserver.create_last_value()
    ex.add_observer(observer)
    outs = [ref(o) for o in sc["outputs"]]
    stop, rows, steps, ok, message, t0 = sc["stop_time"], [], 0, True, "ok", time.perf_counter()
    while ex.status().current_time * 1e-9 < stop * (1 - 1e-12):
        if steps >= sc["budget"]:
            ok, message = False, f"more than {sc['budget']} macro steps"
            break
        if not ex.step():
            ok, message = False, f"libcosim stopped at t = {ex.status().current_time * 1e-9!r} (step failed)"
            break
        steps += 1
        rows.append([ex.status().current_time * 1e-9] + [observer.last_real_values(s, [r])[0] for s, r in outs])
    counters = [observer.last_integer_values(index[n], [refs[n]["nDoStep"]])[0] for n in index if "nDoStep" in refs[n]]
    print(json.dumps({"success": ok, "message": message, "rows": rows, "steps": steps, "counted": sum(counters),
                      "counters": len(counters), "seconds": time.perf_counter() - t0}), flush=True)
'''


def run_ecco(sc, system, size):
    """ECCO at each tolerance of the scenario (one subprocess for all of them); none without libcosimpy."""
    if importlib.util.find_spec("libcosimpy") is None:
        print(f"  {ECCO_MISSING}", flush=True)
        return []
    runs, settings = [], []
    for tol in sc.settings("ecco", size):
        runs.append({**ECCO_TEST, "max_step_size": sc.max_step, "abs_tolerance": tol,
                     "rel_tolerance": tol})
        settings.append(f"libcosim test settings, tol = {tol:g}")
    if size != "quick":
        runs.append(dict(ECCO_DEFAULTS))
        settings.append("libcosimpy EccoParams() defaults")
    job = {"components": system["components"], "connections": system["connections"], "bonds": sc.bonds,
           "outputs": sc.outputs, "start_values": sc.start_values, "stop_time": sc.stop_time, "runs": runs,
           "budget": ECCO_BUDGET}
    proc = subprocess.run([sys.executable, "-c", _ECCO], input=json.dumps(job), capture_output=True, text=True,
                          timeout=7200)
    outs = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode or len(outs) != len(runs):
        raise RuntimeError(f"the ECCO runs failed ({proc.returncode}): {proc.stderr[-2000:]}")
    rows = []
    n_fmus = len(system["components"])
    for setting, params, out in zip(settings, runs, outs):
        data = np.array(out["rows"]).reshape(-1, 1 + len(sc.outputs))  # a row after every macro step
        # ECCO steps every FMU once per macro step (ecco_algorithm.cpp: do_step), and never repeats one
        calls = n_fmus * out["steps"]
        if out["counters"] == n_fmus and out["counted"] != calls:
            raise RuntimeError(f"ECCO made {out['counted']} fmi2DoStep calls for {out['steps']} macro steps")
        rows.append(record(sc, "ECCO", setting, out["success"], out["message"], out["steps"], 0, calls, data[:, 0],
                           data[:, 1:].T, params=params, seconds=out["seconds"]))
    return rows


# -- work at equal error --------------------------------------------------------------------------------------------
def calls_at(rows, target=TARGET):
    """``(calls, how)`` a master needs for ``target``: interpolated in log-log between its successful runs that
    bracket it, else extrapolated from its two most accurate ones by their observed order (``how`` says which);
    ``(nan, why)`` when its runs do not converge."""
    pts = sorted((r["error"], r["calls"]) for r in rows if r["success"] and 0 < r["error"] < math.inf)
    if not pts:
        return math.nan, "no successful run"
    for (e1, c1), (e2, c2) in zip(pts, pts[1:]):
        if e1 <= target <= e2:
            s = 0.0 if e2 == e1 else (math.log(target) - math.log(e1)) / (math.log(e2) - math.log(e1))
            return math.exp(math.log(c1) + s * (math.log(c2) - math.log(c1))), "interpolated"
    if pts[0][0] > target and len(pts) >= 2:
        (e1, c1), (e2, c2) = pts[0], pts[1]
        if e2 > e1 * 1.5 and c1 > c2:
            order = math.log(e2 / e1) / math.log(c1 / c2)  # error ~ calls^-order
            return c1 * (e1 / target) ** (1.0 / order), f"extrapolated (order {order:.2f})"
        return math.nan, "not reached: no convergence"
    if pts[0][0] <= target:
        return float(pts[0][1]), "reached by its least accurate run"
    return math.nan, "not reached"


FAMILIES = ("ours", "ours-fixed", "ECCO", "oms-mav", "oms-mav2", "MasterSim")


def family_rows(rows, family):
    if family == "ECCO":  # the controlled runs; the library defaults are reported but not in the curve
        return [r for r in rows if r["master"] == "ECCO" and "defaults" not in r["setting"]]
    return [r for r in rows if r["master"] == family]


def report(rows, scenarios, size):
    flag = "" if size == "default" else f" --{size}"
    lines = [f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()} ({os.cpu_count()} cores), Python "
             f"{platform.python_version()}; `python examples/bench_master_peers.py{flag}`. "
             "FMU calls: `fmi2DoStep` calls summed over the FMUs, rolled-back attempts included. Error: "
             "`max |y - y*| / max |y*|` over the communication points and the listed outputs.", ""]
    lines += ["### FMU calls at an error of 1e-6", "",
              "| scenario | " + " | ".join(FAMILIES) + " | ours / ECCO |", "|---" * (len(FAMILIES) + 2) + "|"]
    for sc in scenarios:
        sc_rows = [r for r in rows if r["scenario"] == sc.name]
        cells, found = [], {}
        for family in FAMILIES:
            calls, how = calls_at(family_rows(sc_rows, family))
            found[family] = calls
            cells.append("—" if math.isnan(calls) else
                         f"{'~' if how.startswith('extrapolated') else ''}{calls:.3g}")
        ratio = found["ours"] / found["ECCO"] if found["ECCO"] > 0 else math.nan
        if math.isnan(found["ECCO"]) and not math.isnan(found["ours"]):
            ratio_text = "ECCO: no answer"
        else:
            ratio_text = "—" if math.isnan(ratio) else f"{ratio:.2g}"
        lines.append(f"| {sc.name} | " + " | ".join(cells) + f" | {ratio_text} |")
    lines += ["", "`~`: extrapolated from the two most accurate runs by their observed order (no run got there); "
              "`—`: no successful run converges towards it.", ""]
    for sc in scenarios:
        lines += [f"### {sc.name}: {sc.title}", "",
                  f"`[0, {sc.stop_time:g}]`, error in {', '.join(f'`{o}`' for o in sc.outputs)}; first step "
                  f"{sc.h0:g} (ECCO: {ECCO_TEST['step_size']:g}), largest {sc.max_step:g} for every adaptive "
                  "master.", "",
                  "| master | setting | macro steps | rejected | FMU calls | error | outcome |",
                  "|---|---|---|---|---|---|---|"]
        for r in rows:
            if r["scenario"] != sc.name:
                continue
            if not r["success"]:
                outcome = "failed: " + r["message"][:110].replace("|", "/")
            elif r["error"] > 1.0:  # the master's word is reported, and beside it what the reference says
                outcome = "the master reports success; its error is above 1: diverged"
            else:
                outcome = "ok"
            lines.append(f"| {r['master']} | {r['setting']} | {r['steps']} | {r['rejected']} | {r['calls']} | "
                         f"{r['error']:.2e} | {outcome} |")
        lines.append("")
    if not any(r["master"] == "ECCO" for r in rows):
        lines += [f"{ECCO_MISSING}.", ""]
    lines += ["### Settings", "",
              f"- **ours**: `fmu_build.cosimulate` with " + "; ".join(
                  f"{sc.name}: `{', '.join(f'{k}={v!r}' for k, v in sc.ours.items())}`" for sc in scenarios)
              + "; controlled runs `step_control=True`, `atol = rtol`, `step_size` the first step, `max_step` as "
                "above; fixed runs at `H`.",
              f"- **ECCO**: libcosimpy `CosimAlgorithm.create_ecco_algorithm(EccoParams(...))` with "
              f"{', '.join(f'{k} = {v:g}' for k, v in ECCO_TEST.items())}, `max_step_size` as above, "
              "`abs_tolerance = rel_tolerance = tol`; one power bond per "
              "force/velocity (effort/flow) pair. Also one run with libcosimpy's `EccoParams()` defaults ("
              + ", ".join(f"{k} = {v:g}" for k, v in ECCO_DEFAULTS.items()) + ").",
              f"- **oms-mav**, **oms-mav2**: Jacobi with zero-order hold, `min_step = {PEER_MIN_STEP:g}`, safety "
              "0.9, change 0.5 ... 1.5, error exponent 1/2, `atol = rtol` (see the classes `OmsMav`, `OmsMav2`).",
              f"- **MasterSim**: Gauss-Seidel with zero-order hold, step doubling, `atol = rtol / 10`, "
              f"`min_step = {PEER_MIN_STEP:g}`, scale `0.9 / err^(1/2)` within 0.2 ... 2 (class "
              "`MasterSimDoubling`).",
              "- **Not installed, re-implemented**: " + "; ".join(f"{k}: {v}" for k, v in NOT_INSTALLABLE.items())
              + ".", ""]
    return "\n".join(lines)


def plot(rows, scenarios, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(scenarios), figsize=(4.2 * len(scenarios), 3.8), squeeze=False)
    styles = {"ours": "o-", "ours-fixed": "s--", "ECCO": "^-", "oms-mav": "v:", "oms-mav2": "x:", "MasterSim": "d-."}
    for ax, sc in zip(axes[0], scenarios):
        for family in FAMILIES:
            pts = sorted((r["calls"], r["error"]) for r in family_rows(rows, family)
                         if r["scenario"] == sc.name and r["success"] and 0 < r["error"] < 1e3)
            if pts:
                ax.loglog(*zip(*pts), styles[family], label=family, ms=4)
        ax.axhline(TARGET, color="0.7", lw=0.8)
        ax.set_title(sc.name, fontsize=10)
        ax.set_xlabel("FMU calls (fmi2DoStep)")
        ax.grid(True, which="major", alpha=0.3)
    axes[0][0].set_ylabel("error to the monolithic solution")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sizes = parser.add_mutually_exclusive_group()
    sizes.add_argument("--quick", action="store_true", help="the chain only, [0, 2], one run per master")
    sizes.add_argument("--full", action="store_true", help="every setting listed in the scenarios (tens of minutes)")
    parser.add_argument("--only", action="append", choices=sorted(SCENARIOS), help="this scenario only (repeatable)")
    parser.add_argument("--out", type=Path, help="write here instead of out/ (not with --docs)")
    parser.add_argument("--docs", action="store_true", help=HELP)
    parser.add_argument("--report", type=Path, metavar="JSON",
                        help="write the report and figure of a saved run (its bench_master_peers.json), run nothing")
    args = parser.parse_args(argv)
    if args.docs and (args.quick or args.out or args.only):
        parser.error("--docs regenerates the report of every scenario: no --quick, --out or --only with it")
    if args.report and (args.quick or args.full or args.only):
        parser.error("--report writes the report of the saved run as it is: no --quick, --full or --only with it")
    size = "quick" if args.quick else "full" if args.full else "default"
    names = args.only or (["chain"] if args.quick else list(SCENARIOS))
    scenarios = [SCENARIOS[n] for n in names]
    global KEEP_TRAJECTORIES
    KEEP_TRAJECTORIES = args.quick
    for sc in scenarios:
        sc.stop_time = sc.sizes[size].get("stop_time", sc.stop_time)
    rows = []
    if args.report:
        saved = json.loads(args.report.read_text())
        rows, size = saved["rows"], saved.get("size", "default")
        names = list(dict.fromkeys(r["scenario"] for r in rows))
        scenarios = [SCENARIOS[n] for n in names]
        for sc in scenarios:
            sc.stop_time = next(r["stop_time"] for r in rows if r["scenario"] == sc.name)
    else:
        with tempfile.TemporaryDirectory(prefix="lsc_bench_master_peers_") as tmp:
            for sc in scenarios:
                print(f"{sc.name}: {sc.title}", flush=True)
                system = sc.build(Path(tmp) / sc.name)
                rows += run_ours(sc, system, size)
                rows += run_ecco(sc, system, size)
                rows += run_peers(sc, system, size)
    text = report(rows, scenarios, size)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        md, png, raw = (args.out / f"bench_master_peers.{ext}" for ext in ("md", "png", "json"))
    else:
        md, png = output_path("bench_master_peers.md", args.docs), output_path("bench_master_peers.png", args.docs)
        raw = ROOT / "out" / "bench_master_peers.json"
        raw.parent.mkdir(exist_ok=True)
    md.write_text(text + "\n")
    plot(rows, scenarios, png)
    if not args.report:
        raw.write_text(json.dumps({"target": TARGET, "size": size, "rows": rows}, indent=None))
    print(text)
    for p in (md, png, raw):
        print(f"wrote {p}")


if __name__ == "__main__":
    main()
