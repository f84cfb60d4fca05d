"""Reconstruction of HDR images from TE and ML spike streams (torch, CPU-first).

The methods: :mod:`.methods` (the registry and the one entry point, ``reconstruct``),
:mod:`.tfp` and :mod:`.tfi` (training-free), :mod:`.learned` (every learned method and its
weights), :mod:`.net` (the paper's network), :mod:`.baselines` (Spk2ImgNet, BSF, MambaSpike),
:mod:`.learning` (what every learned method shares: layers, alignment, the output head,
inference, weights); :mod:`.decoding` (streams decoded in torch), :mod:`.mulaw` (the
mu-law that compresses HDR light), :mod:`.calibration` and :mod:`.darklaw` (a sensor's
calibration). Training: :mod:`.engine` (clips simulated on the fly), :mod:`.train`.
Judging: :mod:`.metrics`, :mod:`.score`, :mod:`.evaluate` (the harness), :mod:`.report` (Table 1) and :mod:`.names` (its names),
:mod:`.dataset` (stores scored on Dask), :mod:`.scenes`, :mod:`.pictures`.
"""
