"""How many CPUs this process may run on."""

from __future__ import annotations

__all__ = ["usable_cpu_count"]


def usable_cpu_count() -> int:
    """The CPUs this process may use, at least 1 (joblib's count): the fewest of the machine's CPUs,
    its affinity mask (``taskset``, a container's ``--cpuset-cpus``), its cgroup's CPU bandwidth
    limit (a container's ``--cpus``, a Kubernetes CPU limit: a process that counted the host's CPUs
    there would start a worker per host CPU and share two) and ``LOKY_MAX_CPU_COUNT``."""
    from joblib import cpu_count  # imported when asked: an alignment worker process never asks (45 ms of its start)

    return cpu_count(only_physical_cores=False)
