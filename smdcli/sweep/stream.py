"""Time-domain sweeps in chunks of members: the plan of chunks (a function of the family alone, so every run of
one sweep, resumed or on a cluster, computes the same chunks), and one chunk solved and measured, keeping its
time histories or only its metrics. A chunk is solved wherever it is sent: this process or a Dask worker.

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

from smdcli.sweep.family import Family
from smdcli.sweep.members import FamilyResult, metrics, solve_family
from smdcli.sweep.spec import QUANTITIES

KEEPS = ("full", "metrics")
CHUNK_SAMPLES = 1 << 21  # samples per quantity in a chunk (members x time points x DOFs): 16 MB, reused
MAX_LINES = 300  # members kept for an overlay plot; more would be slow and look the same


def drawn_members(count: int) -> np.ndarray:
    """The members an overlay draws: all of a few, else MAX_LINES evenly spaced."""
    return np.unique(np.linspace(0, count - 1, min(count, MAX_LINES)).round().astype(int))


def chunk_plan(family: Family, length: int) -> list[range]:
    """Members in chunks of about CHUNK_SAMPLES samples per quantity: bounded memory whatever the sweep's size."""
    S = len(family)
    size = max(1, min(S, CHUNK_SAMPLES // (length * family.base.n)))
    return [range(start, min(start + size, S)) for start in range(0, S, size)]


def chunk_buffers(family: Family, plan: list[range], length: int) -> dict[str, np.ndarray]:
    """Arrays a chunk's histories can be solved into, one per quantity, reused chunk after chunk."""
    shape = (max(len(members) for members in plan), length, family.base.n)
    return {name: np.empty(shape) for name in QUANTITIES}


def identity(family: Family, method: str | None, keep: str) -> str:
    """A digest of what a sweep computes (scenario text, members, grid, method, what is kept): a partial file
    resumes only the sweep that began it."""
    digest = hashlib.sha256()
    digest.update(family.scenario.text.encode())
    spec = family.spec
    digest.update(repr((spec.kind, spec.parameters, spec.ics, method, keep, family.shape)).encode())
    for array in (family.values, family.x0, family.v0, family.M, family.C, family.K):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


@dataclass
class Chunk:
    """What a chunk of members gives the file: per-member rows from `start` on."""

    start: int
    time: np.ndarray | None  # (k, length) padded with NaN where members' grids differ, else None
    histories: dict[str, np.ndarray] | None  # quantity -> (k, length, n), None when only metrics are kept
    metrics: dict[str, np.ndarray]  # (k, n) each
    success: np.ndarray
    messages: list[str]
    methods: list[str]
    stated: np.ndarray  # (k,) each member's vouched error relative to its peak
    acceleration_stated: float  # the worst member's, for the acceleration (derived from x and v); 0 if not kept
    settling_error: float  # s: how far the worst member's settling time may be off (x's error at the band's edge)
    how: str
    traces: dict[int, tuple[np.ndarray, np.ndarray, bool]]  # member -> (time, plotted quantity (N, n), success)

    def __len__(self) -> int:
        return len(self.success)


def solve_chunk(family: Family, members: range, method: str | None, keep: str, grid: np.ndarray | None,
                length: int, quantity: str, workers: int | None = None,
                progress: Callable[[int], None] | None = None, buffers: dict[str, np.ndarray] | None = None) -> Chunk:
    """Solve and measure members start..stop of the family (grid and length: family.output_grid()'s)."""
    result = solve_family(family.take(members), method, workers, progress, buffers)
    return measure_chunk(family, members, result, keep, grid, length, quantity)


def measure_chunk(family: Family, members: range, result: FamilyResult, keep: str, grid: np.ndarray | None,
                  length: int, quantity: str) -> Chunk:
    """A solved chunk's metrics and status; its histories kept (keep="full") or dropped, apart from the members
    an overlay plot draws."""
    from smdcli.model.accuracy import acceleration_accuracy

    part = family.take(members)
    errors: dict[str, np.ndarray] = {}
    measured = metrics(part, result, errors)
    with np.errstate(invalid="ignore"):
        settling_error = float(np.max(errors["settling_time"], initial=0.0))

    def padded(a: np.ndarray) -> np.ndarray:  # members whose grids are shorter than the family's longest
        if a.shape[1] == length:
            return a
        wide = np.full((a.shape[0], length) + a.shape[2:], np.nan)
        wide[:, :a.shape[1]] = a
        return wide

    histories = {name: padded(getattr(result, name)) for name in QUANTITIES}
    accuracy = 0.0  # the acceleration's, where the file keeps it
    if keep == "full":
        with np.errstate(all="ignore"):
            accuracy = float(np.nanmax(acceleration_accuracy(part.M, part.C, part.K, result.stated_accuracy,
                                                             result.displacement, result.velocity,
                                                             result.acceleration, result.force), initial=0.0))
    time = None if grid is not None else padded(np.broadcast_to(result.time, (len(part), result.time.shape[-1])))
    drawn = drawn_members(len(family))
    traces = {}
    for s in drawn[(drawn >= members.start) & (drawn < members.stop)]:
        row = s - members.start
        t = result.time if time is None else time[row]
        traces[int(s)] = (t, np.array(histories[quantity][row]), bool(result.success[row]))
    return Chunk(members.start, time, histories if keep == "full" else None, measured, result.success,
                 result.messages, result.methods, result.stated_accuracy, accuracy, settling_error, result.how, traces)
