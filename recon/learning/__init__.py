"""The machinery every learned reconstruction method shares, below the methods themselves.

The paper's network (:mod:`tespike.recon.net`) and the learned baselines
(:mod:`tespike.recon.baselines`) build on these pieces; nothing here imports a method
(``tests/test_house.py``): the registry that names the methods and builds them
from weights files is :mod:`tespike.recon.learned`, the trainer :mod:`tespike.recon.train`.

- :mod:`.layers`: the 3 x 3 convolution, upsampling, sub-streams, parameter count;
- :mod:`.deform`: the modulated deformable convolution (DCNv2, eq. 5);
- :mod:`.align`: pyramid deformable alignment, with each method's parts as options;
- :mod:`.head`: the output head (a per-pixel blend of training-free estimates);
- :mod:`.sizes`: presets, JSON round trip and checks of a method's sizes;
- :mod:`.span`: the span of readouts a method sees around its key moment;
- :mod:`.weights`: the weights file, written and read;
- :mod:`.infer`: any method on whole streams, tiled, in bounded memory.
"""
