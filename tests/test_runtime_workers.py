"""A pool worker ends with the process that started it (killed, its pool cannot stop the workers)."""

import os
import signal
import subprocess
import sys
import time

POOL_OWNER = """
import os, sys, time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from service.runtime import exit_with_parent

if __name__ == "__main__":
    pool = ProcessPoolExecutor(max_workers=1, mp_context=get_context(sys.argv[1]), initializer=exit_with_parent)
    print(pool.submit(os.getpid).result(), flush=True)
    time.sleep(120)
"""


def _ended(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/status") as status:
            return any(line.startswith("State:") and "Z" in line for line in status)  # a zombie has ended
    except FileNotFoundError:
        return True


def test_a_pool_worker_ends_when_its_parent_is_killed(tmp_path):
    script = tmp_path / "pool_owner.py"
    script.write_text(POOL_OWNER)
    for context in ("spawn", "fork"):
        owner = subprocess.Popen([sys.executable, str(script), context], stdout=subprocess.PIPE, text=True,
                                 env={**os.environ, "PYTHONPATH": os.getcwd()})
        worker = int(owner.stdout.readline())
        assert not _ended(worker)
        owner.send_signal(signal.SIGKILL)
        owner.wait()
        deadline = time.monotonic() + 10
        while not _ended(worker) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _ended(worker), f"the {context} worker outlived its killed parent"
