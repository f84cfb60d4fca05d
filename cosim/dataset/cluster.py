"""Where dataset work runs: in this process, on a local cluster, or on an existing Dask cluster.

:class:`Runner` takes ``dask.delayed`` tasks and yields their results as they
finish. ``workers=1`` (the default) runs them one after another in this
process with Dask's synchronous scheduler: no server, no extra process.
``workers=N > 1`` starts a :class:`distributed.LocalCluster` of N worker
processes, one thread each, listening on 127.0.0.1 only (their HTTP status
servers too, on free ports), and stops it at the end. ``scheduler=ADDRESS`` (or Dask's own ``scheduler-address`` setting, e.g.
``DASK_SCHEDULER_ADDRESS``) sends the same tasks to a running cluster started
with ``dask scheduler`` / ``dask worker`` (docs/distributed.md).

On a cluster, a task whose worker dies is run again on another worker (Dask
reschedules it; :data:`RETRIES` more attempts are allowed for tasks that
raise); every task here is idempotent, so a retry changes nothing but time.
"""

from __future__ import annotations

import logging
from typing import Iterator, Sequence

from golden.errors import InputError

#: Extra attempts for a task that raised (a worker that dies is handled by the scheduler).
RETRIES = 2


def check_workers(workers: int | None, scheduler: str | None) -> None:
    """Refuse ``--workers`` below 1 and ``--workers`` together with ``--scheduler``."""
    if workers is not None and (type(workers) is not int or workers < 1):
        raise InputError(f"--workers {workers!r} must be an integer >= 1")
    if workers is not None and scheduler:
        raise InputError("--workers and --scheduler exclude each other "
                         "(an existing cluster has its own workers)")


class Runner:
    """Context manager: ``with Runner(workers, scheduler) as run: for i, r in run(tasks): ...``."""

    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        check_workers(workers, scheduler)
        import dask
        self.address = scheduler or (dask.config.get("scheduler-address", None) if workers is None else None)
        self.workers = 1 if workers is None else workers
        self.client = None
        self.cluster = None

    @property
    def where(self) -> str:
        if self.address:
            return f"the Dask cluster at {self.address}"
        if self.cluster is not None:
            return f"a local cluster of {self.workers} worker processes"
        return "this process"

    def __enter__(self) -> "Runner":
        if self.address:
            import dask
            from distributed import Client
            try:                 # Dask's own connect timeout (distributed.comm.timeouts.connect, 30 s)
                self.client = Client(self.address, timeout=dask.config.get("distributed.comm.timeouts.connect"))
            except (OSError, TimeoutError, ValueError) as exc:
                first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                raise InputError(f"cannot reach the Dask scheduler {self.address!r}: {first}") from None
        elif self.workers > 1:
            from distributed import Client, LocalCluster
            self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                        host="127.0.0.1", dashboard_address="127.0.0.1:0",
                                        worker_dashboard_address="127.0.0.1:0",
                                        silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
        return self

    def __exit__(self, *exc) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        self.client = self.cluster = None

    def __call__(self, tasks: Sequence) -> Iterator[tuple[int, object]]:
        """Run ``dask.delayed`` tasks; yield (index in ``tasks``, result) as each finishes.

        An exception of a task is raised here (its original type: an
        :class:`InputError` stays one) after the other tasks are cancelled.
        """
        tasks = list(tasks)
        if self.client is None:
            import dask
            for index, task in enumerate(tasks):
                yield index, dask.compute(task, scheduler="sync")[0]
            return
        from distributed import as_completed
        futures = self.client.compute(tasks, retries=RETRIES)
        index_of = {id(future): index for index, future in enumerate(futures)}
        try:
            for future in as_completed(futures):
                yield index_of[id(future)], future.result()
        finally:
            self.client.cancel(futures)
