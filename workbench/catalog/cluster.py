"""Dask clusters for the catalogue: a local cluster of worker processes bound to localhost, or an existing scheduler
(several machines, Slurm/PBS through dask-jobqueue)."""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator

from workbench.catalog.units import warm_worker
from workbench.errors import WorkbenchError
from workbench.robots.ik import children_without_sigint


class ClusterError(WorkbenchError):
    """The Dask cluster could not be started or reached."""


# A local cluster's housekeeping, made coarser for a batch of CPU-bound units of 0.1-2 s each. Dask's defaults suit
# interactive work: the event loops' tick monitor every 20 ms, the nanny's memory monitor every 100 ms, the system
# monitor every 500 ms and the workers' statistical profiler every 10 ms cost about 0.9 CPU-seconds in every 10 s
# with 2 idle workers (measured from /proc/stat), 5% of this 2-core machine, taken from the units; with these, 0.1.
# The dashboard keeps its task stream and progress; its Profile page stays empty and its system plots update every 2 s.
# A value the user set in their Dask configuration wins.
BATCH_CONFIG = {
    "distributed.admin.tick.interval": "500ms",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.profile.enabled": False,
}


def batch_config() -> dict:
    """`BATCH_CONFIG` less the keys whose value the user changed from Dask's default."""
    import dask
    import distributed  # noqa: F401 - adds distributed's defaults to dask.config.defaults

    defaults = dask.config.merge(*dask.config.defaults)
    out = {}
    for key, value in BATCH_CONFIG.items():
        default = dask.config.get(key, config=defaults)
        if dask.config.get(key, default) == default:
            out[key] = value
    return out


@contextmanager
def cluster_client(workers: int | None = None, scheduler: str | None = None, dashboard: bool = True,
                   quiet: bool = True) -> Iterator["distributed.Client"]:  # noqa: F821
    """A `distributed.Client` on a new `LocalCluster` of `workers` single-threaded worker processes (default: all
    cores) on 127.0.0.1, or on the scheduler at `scheduler` (tcp://host:8786); closed (and the cluster shut down) on
    exit. Worker processes start with the `spawn` method, so nothing is forked from a threaded process; each starts with
one BLAS/OpenMP thread (Dask's `distributed.nanny.pre-spawn-environ`), and imports the units' modules and builds its
hand before the client is handed out (`warm_worker`). Its housekeeping intervals are `BATCH_CONFIG`'s."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None and workers is not None:
        raise ClusterError("give either --workers (a local cluster) or --scheduler (an existing one), not both")
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise ClusterError(f"no Dask scheduler answers at {scheduler} ({type(exc).__name__}); start one with "
                               f"`dask scheduler` or check the address") from None
        try:
            _warm(client)
            yield client
        finally:
            client.close()
        return
    n = (os.cpu_count() or 1) if workers is None else int(workers)
    if n < 1:
        raise ClusterError(f"--workers must be at least 1, got {workers}")
    with dask.config.set({"distributed.worker.multiprocessing-method": "spawn", **batch_config()}):
        with children_without_sigint(other_threads=True):  # Ctrl-C is the driver's: the workers never see it
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address="127.0.0.1:0" if dashboard else None, silence_logs=50 if quiet else 20)
        client = Client(cluster)
        try:
            _warm(client)  # imports and the hand: start-up, not the build's time
            yield client
        finally:
            client.close()
            cluster.close()


def _warm(client) -> None:
    """Every worker imports the units' modules and builds its hand now (`warm_worker`); a worker that cannot (another
    environment on a remote machine) is a ClusterError, not a traceback."""
    try:
        client.run(warm_worker)
    except Exception as exc:  # noqa: BLE001 - whatever the remote worker raised, reported in one line
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise ClusterError(f"a Dask worker cannot load the workbench ({type(exc).__name__}: {first}); "
                           f"start the workers from the same environment (venv, PYTHONPATH)") from None


def dashboard_link(client) -> str:
    """The dashboard's address, with a note when the scheduler serves none or bokeh is missing for its pages."""
    import importlib.util

    if "dashboard" not in client.scheduler_info().get("services", {}):
        return "none (the scheduler runs without a dashboard)"
    link = client.dashboard_link
    if importlib.util.find_spec("bokeh") is None:
        return f"{link} (its pages need bokeh: pip install 'regrasp-workbench[catalog]')"
    return link
