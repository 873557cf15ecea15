"""One Dask cluster per test process and worker count, joined by the services of the test modules that need
nothing of a cluster but its workers.

Each such module started a LocalCluster of its own, some 40 times a run: a worker process's start and
imports cost about 2.5 s of CPU, and a cluster's close half a second of wall. A module joins the shared
cluster as a service joins an external scheduler (``Settings(scheduler_address=shared_scheduler(n))``, or
a ``distributed.Client`` of that address), so its workers start once per test process and keep what they
imported and loaded (warm suite 4 min 57 s -> 4 min 6 s, 491 -> 407 s of CPU).

A module keeps a cluster of its own when its test needs one: it kills or restarts workers, starts them
with an environment of its own, or checks what a cluster the service starts looks like (its interfaces,
dashboard, plugin, warm-up). The workers of a shared cluster start with the environment of the test
process at its first use: a variable set later does not reach them.
"""

from __future__ import annotations

from typing import Any

from isolab.service.api.app import service_cluster

_CLUSTERS: dict[int, Any] = {}


def shared_scheduler(workers: int) -> str:
    """The address of this test process's cluster of ``workers`` worker processes, the one the service
    starts (``service.api.app.service_cluster``), started at its first use and closed when the test
    process ends (:func:`close_shared_clusters`)."""
    cluster = _CLUSTERS.get(workers)
    if cluster is None or cluster.status.name != "running":
        cluster = service_cluster(workers)
        _CLUSTERS[workers] = cluster
    return str(cluster.scheduler_address)


def close_shared_clusters() -> None:
    """Close every cluster :func:`shared_scheduler` started in this process."""
    while _CLUSTERS:
        _, cluster = _CLUSTERS.popitem()
        cluster.close()
