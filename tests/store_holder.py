"""An on-disk store held open by another process, as a running ``graphtwin serve`` holds it."""

import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

from service.graph.store import GraphStore


@contextmanager
def held_by_another_process(path: Path):
    """Create the store at ``path`` (then close it), open it in a child process for the ``with``
    block, and let the child exit after."""
    GraphStore.embedded(path)
    holder = subprocess.Popen(
        [sys.executable, "-c", f"import sys, pyoxigraph; s = pyoxigraph.Store({str(path)!r}); print('open', flush=True); sys.stdin.read()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "open"
        yield path
    finally:
        holder.communicate("", timeout=30)
