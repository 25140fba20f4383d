"""Interrupts (Ctrl-C, SIGTERM) that are never lost.

A signal is recorded before it is raised as KeyboardInterrupt, so even when
the exception is swallowed (Python ignores exceptions raised inside weakref
callbacks and __del__, which h5py and numpy run), the record stays: a file is
only renamed onto its final name while no signal has been received, with
signals held for the check and the rename, and the process's exit code is
decided the same way. Imports nothing from smd.
"""

from __future__ import annotations

import math
import os
import signal
import threading
from contextlib import contextmanager

SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})
_received: int | None = None
_deferring = 0  # inside deferred(): a signal is recorded, and raised when the block ends


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so that files being written are removed on the way out."""


def _handler(signum, frame):
    global _received
    _received = _received or signum
    if _deferring:
        return
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def _record(signum, frame):
    global _received
    _received = _received or signum


def settle() -> int | None:
    """Stop raising on SIGINT and SIGTERM, then ignore them; the first signal received at any point, or None.

    They are ignored, not left to a Python handler, because Python resets its own handlers to the default (die
    with the signal) while the interpreter shuts down. A signal that lands while the handlers are being switched
    still raises once (Python runs a pending handler between any two bytecodes, even inside the switching call):
    it is recorded all the same and the switch is retried, so no interrupt escapes as a traceback at the end."""
    while True:
        try:
            for signum in SIGNALS:
                signal.signal(signum, _record)
            for signum in SIGNALS:
                signal.signal(signum, signal.SIG_IGN)
            return received()
        except KeyboardInterrupt:
            continue


def install() -> None:
    """Record and raise SIGINT and SIGTERM (call once, from the main thread). A signal ignored when smd started
    stays ignored, as Unix programs do (a shell script's background job `smd ... &` ignores Ctrl-C)."""
    import sys

    for signum in SIGNALS:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, _handler)
    default = sys.unraisablehook

    def unraisable(info) -> None:
        # An interrupt raised inside a weakref callback or __del__ cannot propagate; it is recorded, so no
        # "Exception ignored" traceback: the run still stops at the next check with 130/143. Once one has been
        # received, an object it cut short in its constructor may fail in its own __del__ (llvmlite's pass
        # options, interrupted while numba compiled: "no attribute '_as_parameter_'"): the run is ending with its
        # one line, so that is not printed either
        if not isinstance(info.exc_value, KeyboardInterrupt) and _received is None:
            default(info)

    sys.unraisablehook = unraisable


def received() -> int | None:
    """The first signal received, recorded even if its exception was swallowed; a held one counts too."""
    if _received is None and hasattr(signal, "sigpending"):
        held = signal.sigpending() & SIGNALS
        if held:
            return min(held)
    return _received


def exit_code(signum: int) -> int:
    """What a shell expects of a process stopped by this signal: 130 for SIGINT, 143 for SIGTERM."""
    return 128 + int(signum)


@contextmanager
def held():
    """Hold SIGINT and SIGTERM in the block: one that arrives waits until the block ends, then raises."""
    if not hasattr(signal, "pthread_sigmask"):  # Windows: no signal masks; the check in commit still applies
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def raise_if_received() -> None:
    """Raise the interrupt a received signal stands for (KeyboardInterrupt or Terminated)."""
    signum = received()
    if signum is not None:
        raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


@contextmanager
def deferred(raise_after: bool = True):
    """In the block a signal is recorded, not raised: an exception raised inside a lock's wait (a thread pool's
    future, a thread's join) leaves the lock inconsistent, and the thread that next uses it fails ("release
    unlocked lock"). With raise_after, a signal received by the end of the block raises there."""
    global _deferring
    import threading

    if threading.current_thread() is not threading.main_thread():  # signals are only ever raised in the main one
        yield
        return
    if _received is not None:  # waiting on other threads after an interrupt: first free what it may have left held
        _release_import_lock()
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
    if raise_after:
        raise_if_received()


def _release_import_lock() -> None:
    """Release the interpreter's import lock where this thread still holds it: a signal raised in the instant
    between importlib's taking it and the `try` that gives it back (`_imp.acquire_lock()` then `try:`) leaves it
    held, and a worker thread that then imports anything waits for it forever while this thread waits for the
    worker (an interrupted sweep hung so under load, its solver thread in `_imp.acquire_lock`). smd's own code never
    runs inside importlib's locked sections, so a lock this thread holds here is such a leftover."""
    import _imp

    while _imp.lock_held():
        try:
            _imp.release_lock()
        except RuntimeError:  # another thread's, taken for its own import: its to give back
            return


SLICE = 0.1  # s: how long one deferred wait lasts before a received signal is raised


def result(future, timeout_error=TimeoutError):
    """future.result(), waited for in slices with signals deferred, so that an interrupt raises between slices,
    never inside the future's lock."""
    while True:
        with deferred():
            try:
                return future.result(timeout=SLICE)
            except timeout_error:
                pass


def submit(pool, function, *args):
    """pool.submit(function, *args) with signals deferred: submitting takes the pool's locks (a thread pool's
    idle-thread semaphore), and an interrupt raised while one is held leaves it held, so that the pool's threads
    wait on it forever and so does the shutdown that joins them."""
    with deferred():
        return pool.submit(function, *args)


def cgroup_cpu_quota(root: str = "/sys/fs/cgroup") -> float | None:
    """The CPUs a container's quota allows this process (docker --cpus; cgroup v2's cpu.max or v1's CFS quota), or
    None where there is none or it cannot be read."""
    from pathlib import Path

    folder = Path(root)
    try:
        quota, period = (folder / "cpu.max").read_text().split()[:2]
        return None if quota == "max" else int(quota) / int(period)
    except (OSError, ValueError):
        pass
    try:
        quota, period = (int((folder / "cpu" / name).read_text()) for name in ("cpu.cfs_quota_us", "cpu.cfs_period_us"))
        return quota / period if quota > 0 and period > 0 else None
    except (OSError, ValueError):
        return None


_usable_cores: int | None = None


def usable_cores() -> int:
    """The cores this process may run on at once: its CPU affinity, capped by a container's CPU quota. os.cpu_count()
    is the host's: in a container limited to 2 of 64 cores, 64 threads each waited their turn (a 200-period spectrum
    on 2 cores: 8.3 ms in 64 threads where 2 take 3.3)."""
    global _usable_cores
    if _usable_cores is None:
        try:
            cores = len(os.sched_getaffinity(0))
        except AttributeError:  # macOS, Windows
            cores = os.cpu_count() or 1
        quota = cgroup_cpu_quota()
        _usable_cores = max(1, min(cores, math.ceil(quota)) if quota else cores)
    return _usable_cores


POOL_PREFIX = "smd-in-threads"  # the shared pool's threads' names
_pool: tuple | None = None  # (the process id it was started in, the pool): kept, as starting threads costs each call
_pool_lock = threading.Lock()


def _shared_pool():
    """in_threads' pool, started once a process (a forked child starts its own: the parent's threads are not in it)."""
    global _pool
    with _pool_lock:
        if _pool is None or _pool[0] != os.getpid():
            from concurrent.futures import ThreadPoolExecutor

            _pool = (os.getpid(), ThreadPoolExecutor(max(4, usable_cores()), thread_name_prefix=POOL_PREFIX))
        return _pool[1]


def in_threads(function, tasks: list) -> list:
    """function over tasks, the first in this thread and the others in a pool kept across calls, results in order,
    waited for with signals deferred (never raised inside the pool's locks): for compiled kernels, which no signal
    stops before they return anyway. A pool of its own per call cost 0.30 ms where the kept one costs 0.06 (two
    tasks), a tenth of a 200-period spectrum. Called from the pool's own threads, the tasks run in turn there: a
    worker that waited on the pool could wait for itself."""
    from concurrent.futures import wait

    with deferred():
        if len(tasks) <= 1 or threading.current_thread().name.startswith(POOL_PREFIX):
            return [function(task) for task in tasks]
        futures = [_shared_pool().submit(function, task) for task in tasks[1:]]
        try:
            first = function(tasks[0])
        finally:
            wait(futures)
        return [first] + [future.result() for future in futures]


@contextmanager
def alongside(chores: list):
    """A pool thread does the chores (callables) in turn while the block runs here; the block gets ready, and ready(i)
    returns once chores 0..i are done: it does here the first of them not yet begun and, while it waits for one under
    way, the last ones not begun, so that the block waits for nothing the two threads could do; it returns the last
    chore k >= i with 0..k done. The block ends once the chores are done too. Memory-bound chores overlap a compiled
    kernel this way: output rows zeroed on the second core ahead of the kernel that sums into them. In turn, before
    the block, where one core is all there is or this is a pool thread."""
    from concurrent.futures import wait

    last = len(chores) - 1
    if not chores or usable_cores() < 2 or threading.current_thread().name.startswith(POOL_PREFIX):
        for chore in chores:
            chore()
        yield lambda i: last
        return
    done = [threading.Event() for _ in chores]
    open_ends, claiming = [0, len(chores)], threading.Lock()  # the chores not begun: open_ends[0] .. open_ends[1] - 1

    def claim(needed: int) -> int | None:
        """The first chore not begun if it is at most needed, else the last one not begun: now this thread's."""
        with claiming:
            first, end = open_ends
            if first >= end:
                return None
            if first <= needed:
                open_ends[0] = first + 1
                return first
            open_ends[1] = end - 1
            return end - 1

    def do(i: int) -> None:
        chores[i]()
        done[i].set()

    def in_turn():
        try:
            while (i := claim(last)) is not None:
                do(i)
        finally:  # a chore that raised: the block waits no longer, and the raise comes after it
            for event in done:
                event.set()

    def ready(i: int) -> int:
        while not done[i].is_set():
            j = claim(i)
            if j is None:
                done[i].wait()
            else:
                do(j)
        for event in done[:i]:
            event.wait()
        while i < last and done[i + 1].is_set():
            i += 1
        return i

    with deferred():
        future = _shared_pool().submit(in_turn)
        try:
            yield ready
        finally:
            wait([future])
        future.result()


def settled(future) -> None:
    """Wait for a future to finish, whatever signals arrive meanwhile (cleanup after an interrupt)."""
    with deferred(raise_after=False):
        future.exception()
