"""A sweep's chunks on a Dask cluster: an existing scheduler by address, or a LocalCluster of worker processes
(`--scheduler local`). Each chunk is one task running the same solve_chunk as this process would, so the
numbers are the same whichever runs them; results come back in any order and are handed on in plan order.
dask.distributed is an optional extra, imported only here.

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import logging
from typing import Callable, Iterator

import numpy as np

from smdcli.errors import UsageError
from smdcli.sweep.family import Family
from smdcli.sweep.pool import default_workers
from smdcli.sweep.stream import Chunk, solve_chunk

INSTALL = "pip install -e '.[dask]'"  # what a user without dask.distributed is told


# Transports a plain address can use; tls:// and wss:// need certificates, ucx:// the UCX library, inproc:// a
# scheduler inside this very process: none can be given on a command line.
SCHEMES = ("tcp", "ws")


def check_address(scheduler: str) -> None:
    """Refuse, before connecting, an address whose transport smd cannot use from the command line."""
    scheme, sep, rest = scheduler.partition("://")
    if not sep:
        scheme, rest = "tcp", scheduler
    if scheme not in SCHEMES:
        why = {"tls": "needs TLS certificates", "wss": "needs TLS certificates", "ucx": "needs the UCX transport",
               "inproc": "names a scheduler inside one Python process"}.get(scheme, "is not a Dask transport")
        raise UsageError(f"--scheduler {scheduler}: the scheme {scheme}:// {why}; expected tcp://HOST:PORT (or "
                         "HOST:PORT), ws://HOST:PORT, or local")
    host, _, port = rest.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(f"--scheduler {scheduler}: expected an address HOST:PORT with a port from 1 to 65535")
    import socket

    try:  # a refused or unroutable port is told at once, not after distributed's 10 s of retries
        socket.create_connection((host.strip("[]"), int(port)), timeout=2).close()
    except OSError as exc:
        raise UsageError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there "
                         f"({exc.strerror or 'timed out'})") from None


def _quiet_resource_tracker() -> None:
    """Keep the resource tracker's 'leaked semaphore objects to clean up' warning (its clean-up goes on) out of the
    terminal, by the environment the tracker process starts with."""
    import os

    quiet = "ignore::UserWarning:multiprocessing.resource_tracker"
    given = os.environ.get("PYTHONWARNINGS")
    if quiet not in (given or ""):
        os.environ["PYTHONWARNINGS"] = f"{given},{quiet}" if given else quiet


class Cluster:
    """A Client on the scheduler at an address, or on a new LocalCluster of `workers` processes; close() ends both."""

    def __init__(self, scheduler: str, workers: int | None = None):
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise UsageError(f"--scheduler needs dask.distributed, which is not installed: {INSTALL}") from None
        self.local = None
        self.where = "a LocalCluster" if scheduler == "local" else f"the cluster at {scheduler}"
        if scheduler == "local":
            # the workers' semaphores, left when an interrupt stops them, are unlinked by multiprocessing's resource
            # tracker (a process the cluster starts) as it ends, with a warning for each batch: under PYTHONUNBUFFERED
            # (Docker images set it) three lines of it followed smd's one-line message on SIGTERM
            _quiet_resource_tracker()
            self.local = LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1, processes=True,
                                      dashboard_address=None, silence_logs=logging.CRITICAL)
            self.client = Client(self.local)
        else:
            check_address(scheduler)
            try:
                self.client = Client(scheduler, timeout="10s")
            except Exception as exc:  # distributed raises OSError, TimeoutError, ValueError, TypeError... by transport
                raise UsageError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there "
                                 f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None

    def close(self) -> None:
        """Disconnect, and stop the LocalCluster if this started one. Tasks cut short by an interrupt are expected
        then: distributed's log lines and tracebacks about them would only bury smd's one-line message."""
        logging.getLogger("distributed").setLevel(logging.CRITICAL)
        self.client.close()
        if self.local is not None:
            self.local.close()

    def chunks(self, family: Family, plan: list[range], method: str | None, keep: str, grid: np.ndarray | None,
               length: int, quantity: str, progress: Callable[[int], None] | None = None) -> Iterator[Chunk]:
        """Solve the plan's chunks as tasks; yield them in plan order. At most a few chunks per worker thread are in
        flight or waiting to be yielded, so the client's memory stays bounded whatever the sweep's size."""
        from distributed import as_completed

        client = self.client
        window = 2 * max(1, sum(client.nthreads().values())) + 2
        shared = client.scatter(family, broadcast=True)  # sent once to every worker, not once per task
        todo = iter(enumerate(plan))
        waiting = as_completed()
        done: dict[int, Chunk] = {}
        ahead = 0  # the next chunk to yield

        def submit() -> None:
            task = next(todo, None)
            if task is not None:
                waiting.add(client.submit(_task, *task, shared, method, keep, grid, length, quantity, pure=False))

        for _ in range(window):
            submit()
        for future in waiting:
            k, chunk = future.result()
            done[k] = chunk
            future.release()
            if progress:
                progress(len(chunk))
            while ahead in done:
                yield done.pop(ahead)
                ahead += 1
                submit()


def _task(k: int, members: range, family: Family, method, keep, grid, length, quantity) -> tuple[int, Chunk]:
    """On a worker: one chunk, on one thread (the cluster's workers are the parallelism)."""
    return k, solve_chunk(family, members, method, keep, grid, length, quantity, workers=1)
