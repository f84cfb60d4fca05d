"""Dataset work on Dask: the runner, synthesis into a store, the command-line side of store evaluation."""
