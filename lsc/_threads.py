"""BLAS threads for the set-ups: chosen here, not inherited from the environment.

The dense and structured set-ups are LAPACK-bound (LU, QR, SVD of n-sized
blocks and derivative arrays). OpenBLAS's threads busy-wait: on a 2-core
machine shared with other processes, the structured set-up of an index-3
pencil at n = 1,000 took 2.5 to 3.6 times longer with two threads than with
one (498 constraints) and 1.6 to 3.8 times (5 constraints) at a load average
of 4 to 5, and 5 to 6 times at 9, measured side by side
(examples/bench_sparse.py ``--threads``, docs/reference/benchmarks.md).
One thread is therefore the default;
``LSC_BLAS_THREADS`` (a positive int) overrides it for machines whose cores
are the set-up's alone. `threadpoolctl` changes the count for the duration
of a set-up only, so the caller's own setting is restored after it.
"""

import os
from contextlib import contextmanager

__all__ = ["SETUP_THREADS", "blas_threads", "setup_threads"]

SETUP_THREADS = 1
_controller = None


def setup_threads():
    """The BLAS thread count for a set-up: ``LSC_BLAS_THREADS`` if set, else `SETUP_THREADS`."""
    text = os.environ.get("LSC_BLAS_THREADS", "").strip()
    if not text:
        return SETUP_THREADS
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise ValueError(f"LSC_BLAS_THREADS must be a positive int; found {text!r}.")
    return value


@contextmanager
def blas_threads(limit=None):
    """Run the block with `limit` BLAS threads (default `setup_threads()`), restoring the previous count after."""
    global _controller
    limit = setup_threads() if limit is None else limit
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - a declared dependency; without it the environment's count stays
        yield
        return
    if _controller is None:
        _controller = ThreadpoolController()
    with _controller.limit(limits=limit, user_api="blas"):
        yield
