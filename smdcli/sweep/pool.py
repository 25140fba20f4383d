"""Running member tasks: on threads where the work is compiled kernels (they release the GIL), else a process
pool of --workers; progress reported from long tasks step by step.

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import sys
import threading
from typing import Callable, Iterator

from smdcli import interrupts

_TICKS = None  # in a worker: where it reports finished steps of a long task (see run_pool's steps mode)


def _set_ticks(queue) -> None:
    """A worker process's start: where it reports steps; Ctrl-C is the parent's to handle (it stops the workers),
    so that no worker prints a traceback of its own, nor a warning."""
    import os
    import signal
    import warnings

    global _TICKS
    _TICKS = queue
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if not os.environ.get("SMD_DEBUG"):  # as in the parent (cli.run): smd's own lines say what went wrong
        warnings.simplefilter("ignore")


def _tick() -> None:
    """A worker reports one finished step of its task (a frequency of a measured response)."""
    if _TICKS is not None:
        _TICKS.put(1)


class _Inline:
    """The queue's put, for tasks run in this process: straight to the progress bar, one thread at a time."""

    def __init__(self, progress):
        self.lock = threading.Lock()
        self.progress = progress

    def put(self, count: int) -> None:
        with self.lock:
            self.progress(count)


def _slices(futures: list) -> Iterator[list[int]]:
    """The indices of the futures that finished in each slice of waiting (interrupts.SLICE; an empty list where none
    did), until all have; signals deferred while waiting. One queue read per future: concurrent.futures.wait arms a
    waiter on every pending future at each call, and so took a third of a sweep of 2,400 small members on threads
    (14 s, now 9.5 s)."""
    import queue

    finished: queue.SimpleQueue = queue.SimpleQueue()
    with interrupts.deferred():
        for i, future in enumerate(futures):
            future.add_done_callback(lambda _, i=i: finished.put(i))
    left = len(futures)
    while left:
        indices = []
        with interrupts.deferred():
            try:
                indices.append(finished.get(timeout=interrupts.SLICE))
                while True:
                    indices.append(finished.get_nowait())
            except queue.Empty:
                pass
        left -= len(indices)
        yield indices


def run_threads(function: Callable, tasks: list, workers: int, progress: Callable[[int], None] | None = None,
                steps: bool = False) -> list:
    """Results of function over tasks, in order, on a thread pool: for tasks whose work is compiled kernels, which
    release the GIL, so members share this process's memory and kernels (no pickling, no start-up per worker).
    Progress advances by one per task, or with steps=True by the tasks' own steps (_tick)."""
    global _TICKS
    from concurrent.futures import ThreadPoolExecutor

    from smdcli.solvers.integrators.compiled import warm

    warm()  # once, here: threads must not race to compile
    results: list = [None] * len(tasks)
    reporter = _Inline(progress) if progress else None
    _TICKS = reporter if steps else None
    pool = ThreadPoolExecutor(max_workers=max(1, min(workers, len(tasks))))
    # A thread back from a kernel (GIL released) waits for the GIL at most this long, not the default 5 ms: with
    # ~1 ms kernels between short Python stretches, 2,000 members on 2 threads took 3.5 s at 5 ms, 2.5 s at 0.5 ms.
    interval = sys.getswitchinterval()
    sys.setswitchinterval(5e-4)
    try:
        futures = [interrupts.submit(pool, function, task) for task in tasks]
        for finished in _slices(futures):
            with interrupts.deferred():  # an interrupt raises between slices, never inside a pool's or future's lock
                for i in finished:
                    results[i] = futures[i].result()
                    if reporter and not steps:
                        reporter.put(1)
    finally:
        with interrupts.deferred(raise_after=False):
            pool.shutdown(wait=True, cancel_futures=True)
        sys.setswitchinterval(interval)
        _TICKS = None
    return results


def run_pool(function: Callable, tasks: list, workers: int, progress: Callable[[int], None] | None = None,
             steps: bool = False) -> list:
    """Results of function over tasks, in order: inline for one worker, else in a process pool.

    Progress advances by one per task; with steps=True the tasks report finer steps themselves
    (through _tick), passed back over a queue.
    """
    global _TICKS
    results: list = [None] * len(tasks)
    if workers <= 1 or len(tasks) <= 1:
        _TICKS = _Inline(progress) if (steps and progress) else None
        try:
            for i, task in enumerate(tasks):
                results[i] = function(task)
                if progress and not steps:
                    progress(1)
        finally:
            _TICKS = None
        return results
    import multiprocessing
    import queue as queue_mod
    from concurrent.futures import ProcessPoolExecutor

    ticks = multiprocessing.get_context().Queue() if (steps and progress) else None
    pool = ProcessPoolExecutor(max_workers=min(workers, len(tasks)), initializer=_set_ticks, initargs=(ticks,))
    try:
        futures = [interrupts.submit(pool, function, task) for task in tasks]
        for finished in _slices(futures):
            with interrupts.deferred():
                for i in finished:
                    results[i] = futures[i].result()
                    if progress and not steps:
                        progress(1)
            while ticks is not None:
                try:
                    ticks.get_nowait()
                except queue_mod.Empty:
                    break
                progress(1)
    except BaseException:
        with interrupts.deferred(raise_after=False):
            for process in list(getattr(pool, "_processes", {}).values()):  # tasks cut short: stop at once
                process.terminate()
        raise
    finally:
        with interrupts.deferred(raise_after=False):
            pool.shutdown(wait=True, cancel_futures=True)
    return results


def default_workers() -> int:
    """The number of cores this process may use."""
    return interrupts.usable_cores()
