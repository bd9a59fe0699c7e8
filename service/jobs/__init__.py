"""The jobs floor: long-running work of the HTTP service as jobs — records, the runner, where the work
runs (threads, processes, Dask) and the job kinds (``docs/http.md``)."""
