"""How many CPUs this process may run on."""

from __future__ import annotations

import os

__all__ = ["usable_cpu_count"]


def usable_cpu_count() -> int:
    """The CPUs this process may be scheduled on (its affinity mask where the OS has one, as
    ``taskset`` or a container's ``--cpuset-cpus`` set it; else every CPU), at least 1."""
    if hasattr(os, "sched_getaffinity"):
        return max(len(os.sched_getaffinity(0)), 1)
    return os.cpu_count() or 1
