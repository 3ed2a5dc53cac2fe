"""The Dask client of the verbs that spread work over processes (``sweep``; also fit for ``golden build``).

A ``LocalCluster`` that shuts down prints, now and then, a ``CommClosedError``
traceback or "Worker process still alive ... killing" from Dask's own
loggers: noise about the cluster's shutdown, not about the user's work. So
the cluster here keeps Dask's loggers at ``ERROR`` while it runs, the client
closes before the cluster, and Dask's loggers are silent while the two close.
Its HTTP server takes a free port, so a second cluster on the machine is no
"Port 8787 is already in use" warning either.
"""

from __future__ import annotations

import contextlib
import logging

__all__ = ["dask_client", "quiet_loggers"]

#: the loggers that report a cluster's shutdown (the workers' nannies, the comms, the event loop)
NOISY = ("distributed", "tornado", "asyncio")


@contextlib.contextmanager
def quiet_loggers(names=NOISY, level=logging.CRITICAL + 1):
    """Raise these loggers' levels, and their children's (Dask sets some children's own), for the ``with``
    block; restore them.

    Parameters
    ----------
    names : tuple of str
        Logger names; every existing logger below one of them (``name.*``) is included.
    level : int
        Level set for the block (default: above ``CRITICAL``, i.e. silent).

    Yields
    ------
    None
    """
    known = [n for n in list(logging.root.manager.loggerDict) if any(n.startswith(p + ".") for p in names)]
    loggers = [logging.getLogger(n) for n in (*names, *known)]
    before = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(level)
    try:
        yield
    finally:
        for lg, b in zip(loggers, before):
            lg.setLevel(b)


@contextlib.contextmanager
def dask_client(scheduler=None, workers=2, threads_per_worker=1, client=None):
    """A ``distributed.Client``: ``client`` itself if given (left open), else one of the cluster at
    ``scheduler``, else of a new ``LocalCluster`` of ``workers`` processes x ``threads_per_worker`` threads.

    The client (and the cluster) made here are closed at the end of the ``with`` block, quietly.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); None makes a local cluster.
    workers : int
        Worker processes of the local cluster (>= 1).
    threads_per_worker : int
        Threads per worker process of the local cluster.
    client : distributed.Client, optional
        An open client to use as is.

    Yields
    ------
    distributed.Client

    Raises
    ------
    ValueError
        For ``workers < 1`` without a scheduler (Dask would wait for a worker forever).
    """
    if client is not None:
        yield client
        return
    from distributed import Client, LocalCluster

    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        if int(workers) < 1:
            raise ValueError(f"a LocalCluster needs at least 1 worker process, got {workers}")
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=int(threads_per_worker), processes=True,
                               dashboard_address=None, scheduler_kwargs={"dashboard_address": ":0"},
                               silence_logs=logging.ERROR)
        client = Client(cluster)
    try:
        yield client
    finally:
        with quiet_loggers():
            client.close()
            if cluster is not None:
                cluster.close()
