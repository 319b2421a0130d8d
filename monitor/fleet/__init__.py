"""The fleet: every machine's logs, commissioned per machine, judged and trended on Dask."""
