"""Dataset work on Dask: the runner (:mod:`.cluster`), building a store by simulating its sequences
(:mod:`.build`), and the command-line side of store evaluation (:mod:`.evaluate`)."""
