"""The CPUs graphtwin's worker processes and threads are counted against (service/runtime.py)."""

import os
import subprocess
import sys

import pytest


def _count(code: str = "", **env: str) -> int:
    script = f"{code}\nfrom service.runtime import usable_cpu_count\nprint(usable_cpu_count())"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, env={**os.environ, **env})
    return int(done.stdout)


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this platform")
def test_a_process_pinned_to_one_cpu_counts_one():
    assert _count("import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})") == 1
    assert _count() == len(os.sched_getaffinity(0))


def test_a_cap_in_the_environment_is_honoured():
    assert _count(LOKY_MAX_CPU_COUNT="1") == 1
