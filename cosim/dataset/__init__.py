"""Dataset work on Dask: the runner (:mod:`.cluster`) and building a store by simulating its
sequences (:mod:`.build`); ``tespike evaluate --store`` (:mod:`tespike.cosim.commands.evaluate_cmd`)
scores one with :func:`tespike.recon.dataset.evaluate.evaluate_store`."""
