"""Dask clients for the tiled conversion and simulation: a LocalCluster, or a scheduler by address."""

from __future__ import annotations

import contextlib
import logging
import warnings
from typing import Any, Iterator

from ..errors import ZMapError

__all__ = ["CONNECT_TIMEOUT", "cpu_figures", "dask_client", "peak_rss_mb"]

#: seconds to wait for a scheduler given by address before giving up (with the command's own
#: start, within the issue's bound of 10 s)
CONNECT_TIMEOUT = 4.0

#: Dask settings for the workers of our own LocalCluster. Dask's statistical profiler samples
#: every thread's stack every 10 ms, CPU that our tile tasks do not need; and its default
#: ``MALLOC_TRIM_THRESHOLD_`` fixes glibc's mmap threshold at 128 KB, so every array a tile
#: task allocates and frees is a fresh mmap with its page faults (4.6x the faults of a plain
#: process in the simulation's tiles). A user's own cluster keeps its own settings.
LOCAL_WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
}


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, MB.

    Linux's ``VmHWM`` (the high-water mark of this process's own memory): ``ru_maxrss``
    would carry the parent's peak across fork and exec, so a worker started by a big
    client would report the client's memory.
    """
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def cpu_figures(results: list[dict]) -> dict:
    """CPU seconds of tile tasks (``pid``, ``cpu_seconds``, ``thread_cpu_seconds`` each), in all
    and on the busiest worker process.

    ``cpu_seconds / cpu_seconds_busiest_worker`` is the speed-up the run would show were
    every worker alone on its core (what the tiles' split allows), whatever else the
    machine was running. ``task_thread_cpu_seconds`` is the tasks' own threads; the rest of
    a worker's CPU is Dask's (event loop, heartbeats).
    """
    per: dict[int, float] = {}
    for r in results:
        per[r["pid"]] = per.get(r["pid"], 0.0) + r.get("cpu_seconds", 0.0)
    total = sum(per.values())
    busiest = max(per.values()) if per else 0.0
    threads = sum(r.get("thread_cpu_seconds", 0.0) for r in results)
    return {"cpu_seconds": round(total, 3), "task_thread_cpu_seconds": round(threads, 3),
            "cpu_seconds_busiest_worker": round(busiest, 3),
            "cpu_split_speedup": round(total / busiest, 3) if busiest > 0 else 0.0}


def _probe(address: str, timeout: float) -> None:
    """A TCP connection to a ``tcp://host:port`` (or ``host:port``) scheduler, or ZMapError naming it.

    Other schemes (``tls://``, ``ucx://``, ...) are left to Dask's own connect.
    """
    import socket

    rest = address[len("tcp://"):] if address.startswith("tcp://") else address
    if "://" in rest:
        return
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit():
        raise ZMapError(f"scheduler address {address!r} is not tcp://host:port")
    host = host.strip("[]") or "127.0.0.1"
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as exc:
        raise ZMapError(f"no Dask scheduler answers at {address} within {timeout:g} s "
                        f"({type(exc).__name__}: {' '.join(str(exc).split())[:120]})") from None


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, *, workers: int = 2, threads_per_worker: int = 1,
                memory_limit: str | None = None) -> Iterator[Any]:
    """A ``dask.distributed.Client``: on ``scheduler`` (address), else on a new LocalCluster.

    The LocalCluster has ``workers`` worker processes of ``threads_per_worker`` threads
    (each restarted by its nanny above ``memory_limit``, e.g. ``"3GB"``; default Dask's
    share of the machine's memory) and is shut down on exit. A scheduler that does not answer within :data:`CONNECT_TIMEOUT`
    seconds raises :class:`zmap.errors.ZMapError` naming its address.
    """
    from . import cluster as _self  # CONNECT_TIMEOUT read at call time (tests shorten it)

    if scheduler:
        _probe(scheduler, _self.CONNECT_TIMEOUT)  # before importing distributed: seconds on a busy machine
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=f"{_self.CONNECT_TIMEOUT}s")
        except Exception as exc:  # refused, timed out, or something that is not a Dask scheduler answering
            raise ZMapError(f"no Dask scheduler answers at {scheduler} within {_self.CONNECT_TIMEOUT:g} s "
                            f"({type(exc).__name__}: {' '.join(str(exc).split())[:160]})") from None
        try:
            yield client
        finally:
            client.close()
        return
    workers = int(workers)
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    import copy

    import dask

    with warnings.catch_warnings(), dask.config.set(LOCAL_WORKER_CONFIG):
        warnings.simplefilter("ignore")  # "port 8787 is already in use" and friends
        # a nanny keeps a shallow merge of the global config, which the end of this block
        # would restore under it: a worker it restarts must get these settings too
        worker_config = copy.deepcopy(dask.config.config)
        cluster = LocalCluster(n_workers=workers, threads_per_worker=int(threads_per_worker), processes=True,
                               dashboard_address=":0", silence_logs=logging.ERROR,
                               memory_limit=memory_limit or "auto", config=worker_config)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def _identity(obj: Any) -> Any:
    return obj


def share(client: Any, obj: Any) -> Any:
    """A future holding ``obj`` for many tasks: sent once, fetched by each worker once.

    Unlike ``Client.scatter``, the object lives in a task of the graph, so when the worker
    holding it dies the scheduler computes it again on another worker (a scattered object
    is lost with its worker, and every task that needs it fails).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "large object in task graph": sent once, on purpose
        return client.submit(_identity, obj, pure=False)
