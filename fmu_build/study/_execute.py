"""Running a study's jobs: serially, or on Dask worker processes."""
import contextlib
import math
import os
import sys
from functools import partial

from ._runs import warm_up

class _Progress:
    """A tqdm bar of runs done, with running and failed counts."""

    def __init__(self, total, done, failed, show):
        self.done, self.failed, self.bar = done, failed, None
        if show:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, initial=done[0], unit="run", desc="sweep")

    def update(self, running):
        if self.bar is not None:
            self.bar.n = self.done[0]
            self.bar.set_postfix(running=running, failed=self.failed[0], refresh=False)
            self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.update(0)
            self.bar.close()


def _local(client):
    """True if the client's workers run on this machine (they can read the FMU's path)."""
    import socket

    hosts = {"127.0.0.1", "localhost", "::1", socket.gethostname()}
    try:
        hosts.add(socket.gethostbyname(socket.gethostname()))
    except OSError:
        pass
    addresses = list(client.scheduler_info().get("workers", {})) or [client.scheduler.address]
    return all(any(f"//{h}:" in a or f"//[{h}]:" in a for h in hosts) for a in addresses)


def _crash_result(exc):
    from distributed import KilledWorker

    if exc is None:
        reason = ""
    elif isinstance(exc, KilledWorker):
        worker = getattr(getattr(exc, "last_worker", None), "address", None)
        reason = ("the worker process running it died (killed, or crashed e.g. by a segmentation fault in the FMU)"
                  + (f": {worker}" if worker else ""))
    else:
        reason = f"{type(exc).__name__}: {exc}"
    return dict(success=False, message=reason, residual_final=math.nan, residual_peak=math.nan, run_time=math.nan,
                steps=0, t=None, x=None, residual=None)


def _execute(runner, payload, settings, jobs, accept, scheduler, n_workers, bar, timeout=None, kind=None):
    """Run `jobs` ``[(tag, point)]`` with `runner`, passing each result to ``accept(tag, result)``.

    Every process that runs jobs first calls ``warm_up(kind, payload,
    settings)`` (imports, the FMU loaded once), so that no run's ``run_time``
    carries a worker's start-up.
    """
    if scheduler == "serial":
        if jobs:
            warm_up(kind, payload, settings)
        for tag, point in jobs:
            bar.update(1)
            accept(tag, runner(payload, point, settings))
        return
    from distributed import Client

    if scheduler is None:
        with _workers_without_the_script():
            _execute_embedded(runner, payload, settings, jobs, accept, n_workers, bar, timeout, kind)
        return
    client = Client(scheduler) if isinstance(scheduler, str) else scheduler
    try:
        if isinstance(payload, str) and payload.lower().endswith(".fmu") and not _local(client):
            with open(payload, "rb") as fh:  # workers elsewhere need not share a file system
                payload = fh.read()
        _run_jobs(client, runner, payload, settings, jobs, accept, bar, timeout, kind)
    finally:
        if isinstance(scheduler, str):
            client.close()


@contextlib.contextmanager
def _workers_without_the_script():
    """Worker processes start without running the calling script's top level.

    multiprocessing's ``spawn`` (Dask's default) runs the parent's ``__main__``
    again in every child, as ``__mp_main__``: a script that calls `sweep`
    without an ``if __name__ == "__main__":`` guard started a study in every
    worker, which failed to start. The runs need only ``fmu_build`` (metrics
    and references are computed in this process), so while the cluster lives
    (its nannies start and restart workers) ``__main__`` names no file or
    module for the children to run.
    """
    main = sys.modules.get("__main__")
    if main is None:
        yield
        return
    saved = {name: main.__dict__[name] for name in ("__file__", "__spec__") if name in main.__dict__}
    main.__dict__.pop("__file__", None)
    main.__spec__ = None
    try:
        yield
    finally:
        main.__dict__.pop("__spec__", None)
        main.__dict__.update(saved)


def _execute_embedded(runner, payload, settings, jobs, accept, n_workers, bar, timeout, kind):
    """The jobs on a LocalCluster of `n_workers` processes, started here and closed at the end."""
    import dask
    from distributed import Client, LocalCluster

    # A run that kills its worker is not retried on another one: it is recorded as failed.
    # Temporary TLS credentials: no other local process can submit code to these workers.
    # temporary-directory: Dask's scratch space goes into the study's folder, removed at the end
    with dask.config.set({"distributed.scheduler.allowed-failures": 0,
                          "temporary-directory": settings.get("workdir")}):
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=50, security=True,
                               local_directory=settings.get("workdir"))  # removed with the study
        client = Client(cluster)
    try:
        _run_jobs(client, runner, payload, settings, jobs, accept, bar, timeout, kind)
    finally:
        client.close()
        cluster.close()


def _run_jobs(client, runner, payload, settings, jobs, accept, bar, timeout, kind=None):
    """Submit at most one run per worker thread; record each result, crash or timeout as it comes."""
    import time
    from concurrent.futures import CancelledError

    from distributed import KilledWorker, wait

    warm = partial(warm_up, kind, payload, settings)
    if jobs:
        try:
            client.run(warm)
        except Exception:  # a worker that cannot warm up fails its runs, which say why
            pass

    # At most one run in flight per worker thread: a worker that dies then takes down only the run
    # it was computing, and a run caught in the crash of another is retried once.
    slots = max(sum(client.nthreads().values()), 1)
    queue, futures, tries = list(jobs), {}, {}

    def submit():
        while queue and len(futures) < slots:
            tag, point = queue.pop(0)
            fut = client.submit(runner, payload, point, settings, pure=False, retries=0)
            futures[fut] = (tag, point, time.monotonic())

    submit()
    bar.update(len(futures))
    while futures:
        try:
            done, _ = wait(list(futures), timeout=0.2 if timeout else None, return_when="FIRST_COMPLETED")
        except TimeoutError:  # nothing finished in this poll: look for runs past their timeout
            done = []
        for fut in done:
            tag, point, _ = futures.pop(fut)
            try:
                result = fut.result()
            except Exception as exc:
                tries[tag] = tries.get(tag, 0) + 1
                if isinstance(exc, (KilledWorker, CancelledError)) and tries[tag] < 2:
                    queue.insert(0, (tag, point))
                    fut.release()
                    continue
                result = _crash_result(exc)
            accept(tag, result)
            fut.release()
        if timeout:
            _end_overdue(client, futures, timeout, accept, warm)
        submit()
        bar.update(len(futures))


def _end_overdue(client, futures, timeout, accept, warm):
    """Record runs past `timeout` as failed and restart the workers computing them."""
    import time

    now = time.monotonic()
    overdue = [fut for fut, (_, _, started) in futures.items() if now - started > timeout]
    if not overdue:
        return
    processing = client.processing()
    workers = {w for w, keys in processing.items() for fut in overdue if fut.key in keys}
    for fut in overdue:
        tag, _, _ = futures.pop(fut)
        fut.cancel()
        accept(tag, dict(_crash_result(None), message=f"timeout: the run took more than {timeout:g} s; "
                                                      "its worker was restarted"))
    if workers:
        # End the worker process at once (a graceful restart waits for the stuck run); its nanny
        # starts a fresh one, and the scheduler moves the worker's other runs.
        workers_before = set(client.scheduler_info()["workers"])
        count = len(workers_before)
        try:
            client.run(os._exit, 1, workers=list(workers))
        except Exception:  # the connection dies with the process
            pass
        gone = time.monotonic() + 30
        while time.monotonic() < gone and workers & set(client.scheduler_info()["workers"]):
            time.sleep(0.1)  # the scheduler notices the death before a fresh worker can be counted
        try:
            client.wait_for_workers(count, timeout=120)
            fresh = sorted(set(client.scheduler_info()["workers"]) - workers_before)
            if fresh:  # a fresh worker imports and loads what the others have: not the next run's time
                client.run(warm, workers=fresh)
        except Exception:  # fewer workers (no nanny to restart it): the study goes on with the others
            pass
    restarted = time.monotonic()
    for fut, (tag, point, _) in list(futures.items()):  # runs queued behind a restart start their clock now
        futures[fut] = (tag, point, restarted)
