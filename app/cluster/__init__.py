"""`slscan decode --scheduler`: decoding dumps on a Dask cluster in resumable chunks (slscan[cluster]).

chunks.py cuts a dump's frame sets into tasks; task.py is what a worker runs (its decoder built once per worker
process); manifest.py is the output folder's record of the run and of the chunks complete; client.py connects to
the scheduler; summary.py counts and reports; zarr_depth.py is `--zarr`'s depth store; run.py ties them together for
the command. Only client.py and run.py import dask.distributed: a worker imports task.py and what it needs.
"""
