"""The Dask cluster of the offline commands: a local one by default, or an existing scheduler.

``windrig reprocess`` and ``windrig bridge --uncertainty`` share it, so that ``--workers N``
and ``--scheduler ADDRESS`` mean the same in both: without ``scheduler`` a ``LocalCluster`` of
``workers`` single-threaded processes (default: the machine's cores) on loopback, with no
dashboard (a laptop run opens no port to the network); with it the client connects to that
scheduler and nothing else changes. Tasks must then be plain picklable functions of plain
arguments: the workers may be other machines.

Not responsible for: what runs on the cluster (the commands' own modules).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["dask_client", "describe"]


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """Yield a ``dask.distributed.Client``; close it (and a local cluster) on the way out.

    Parameters
    ----------
    workers : int, optional
        Local worker processes (default: the machine's cores); ignored with ``scheduler``.
    scheduler : str, optional
        Address of an existing Dask scheduler, e.g. ``tcp://10.0.0.5:8786``.
    """
    # dask is an optional dependency (the ``dask`` extra): only these commands need it.
    from dask.distributed import Client, LocalCluster

    cluster = None
    if scheduler is None:
        n = workers if workers is not None else (os.cpu_count() or 1)
        # Loopback only, no dashboard: a laptop run opens no port to the network.
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None,
                               scheduler_kwargs={"dashboard": False})
    try:
        client = Client(scheduler if scheduler is not None else cluster)
    except BaseException:
        if cluster is not None:
            cluster.close()
        raise
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def describe(workers: int | None, scheduler: str | None) -> str:
    """Name the cluster :func:`dask_client` uses, for output (``local cluster of 2 workers``)."""
    if scheduler is not None:
        return f"Dask scheduler {scheduler}"
    n = workers if workers is not None else (os.cpu_count() or 1)
    return f"local Dask cluster of {n} worker{'s' if n != 1 else ''}"
