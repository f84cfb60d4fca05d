"""The paper's reconstruction network (section 5, Fig. 3): MSFEG, SPA, LIR, in its sizes.

What it shares with the learned baselines (output head, alignment, deformable
convolution, weights, inference) is :mod:`tespike.recon.learning`, the mu-law
:mod:`tespike.recon.mulaw`; its training is :mod:`tespike.recon.train`.
"""
