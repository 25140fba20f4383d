"""Running member tasks: a process pool of --workers, progress reported over a queue from long tasks.

Must not import: io, plots, commands, cli."""

from __future__ import annotations

from typing import Callable

_TICKS = None  # in a worker: where it reports finished steps of a long task (see run_pool's steps mode)


def _set_ticks(queue) -> None:
    global _TICKS
    _TICKS = queue


def _tick() -> None:
    """A worker reports one finished step of its task (a frequency of a measured response)."""
    if _TICKS is not None:
        _TICKS.put(1)


class _Inline:
    """The queue's put, for tasks run in this process: straight to the progress bar."""

    def __init__(self, progress):
        self.put = progress


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
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    ticks = multiprocessing.get_context().Queue() if (steps and progress) else None
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), initializer=_set_ticks,
                             initargs=(ticks,)) as pool:
        futures = {pool.submit(function, task): i for i, task in enumerate(tasks)}
        pending = set(futures)
        try:
            while pending:
                done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                for future in done:
                    results[futures[future]] = future.result()
                    if progress and not steps:
                        progress(1)
                while ticks is not None:
                    try:
                        ticks.get_nowait()
                    except queue_mod.Empty:
                        break
                    progress(1)
        except BaseException:
            for future in futures:
                future.cancel()
            raise
    return results


def default_workers() -> int:
    """The number of cores this process may use."""
    import os

    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1
