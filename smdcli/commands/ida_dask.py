"""`smd ida --scheduler`: a campaign's records as Dask tasks (a record per task; a task whose worker is lost is
rerun elsewhere by Dask, and, the trace a pure function of its task, gives the same numbers).

Must not import: cli.
"""

from __future__ import annotations

from smdcli.errors import UsageError


def run_on_dask(scheduler: str, work, tasks: list[dict], indices: list[int]):
    """Yield (index, work(task)) as each record's task finishes on the scheduler ('local': a local cluster)."""
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UsageError("--scheduler: needs dask.distributed (pip install 'smdcli[dask]')") from None
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True) if scheduler == "local" else None
    try:
        with Client(cluster if cluster is not None else scheduler) as client:
            futures = {client.submit(work, task, pure=True, retries=2): i for task, i in zip(tasks, indices)}
            for future in as_completed(futures):
                yield futures[future], future.result()
    finally:
        if cluster is not None:
            cluster.close()
