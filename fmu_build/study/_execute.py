"""Running a study's jobs: serially, or on Dask worker processes."""
import math

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

    if isinstance(exc, KilledWorker):
        worker = getattr(getattr(exc, "last_worker", None), "address", None)
        reason = ("the worker process running it died (killed, or crashed e.g. by a segmentation fault in the FMU)"
                  + (f": {worker}" if worker else ""))
    else:
        reason = f"{type(exc).__name__}: {exc}"
    return dict(success=False, message=reason, residual_final=math.nan, residual_peak=math.nan, run_time=math.nan,
                steps=0, t=None, x=None, residual=None)


def _execute(runner, payload, settings, jobs, accept, scheduler, n_workers, bar):
    if scheduler == "serial":
        for tag, point in jobs:
            bar.update(1)
            accept(tag, runner(payload, point, settings))
        return
    from concurrent.futures import CancelledError

    import dask
    from distributed import Client, KilledWorker, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        # A run that kills its worker is not retried on another one: it is recorded as failed.
        with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address=None, silence_logs=50)
            client = Client(cluster)
    elif isinstance(scheduler, str):
        client = Client(scheduler)
    else:
        client = scheduler
    try:
        if isinstance(payload, str) and payload.lower().endswith(".fmu") and not _local(client):
            with open(payload, "rb") as fh:  # workers elsewhere need not share a file system
                payload = fh.read()
        slots = max(sum(client.nthreads().values()), 1)
        # At most one run in flight per worker thread: a worker that dies then takes down only
        # the run it was computing, and a run caught in the crash of another is retried once.
        queue, futures, tries = list(jobs), {}, {}
        running = as_completed()

        def submit():
            while queue and len(futures) < slots:
                tag, point = queue.pop(0)
                fut = client.submit(runner, payload, point, settings, pure=False, retries=0)
                futures[fut] = (tag, point)
                running.add(fut)

        submit()
        bar.update(len(futures))
        for fut in running:
            tag, point = futures.pop(fut)
            try:
                result = fut.result()
            except Exception as exc:
                tries[tag] = tries.get(tag, 0) + 1
                if isinstance(exc, (KilledWorker, CancelledError)) and tries[tag] < 2:
                    queue.insert(0, (tag, point))
                    fut.release()
                    submit()
                    continue
                result = _crash_result(exc)
            accept(tag, result)
            fut.release()
            submit()
            bar.update(len(futures))
    finally:
        if cluster is not None:
            client.close()
            cluster.close()

