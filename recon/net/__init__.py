"""The paper's reconstruction network (section 5, Fig. 3): MSFEG, SPA, LIR, in its sizes.

What it shares with the learned baselines (output head, alignment, deformable
convolution, mu-law, weights, inference) is :mod:`tespike.recon.learning`; its
training is :mod:`tespike.recon.train`.
"""
