"""Configurations shared by the tests of every package."""

from tespike.golden.config import SensorConfig

#: Configurations at the edges of every valid range of SPEC section 2, both modes.
EDGE_CONFIGS = [
    SensorConfig(),                                           # paper TE: b1 = b2 = 4
    SensorConfig(mode="ml"),                                  # paper ML: 8 bits
    SensorConfig(b1=1),
    SensorConfig(b2=1),                                       # alpha = 1
    SensorConfig(alpha=1, clocks_per_tick=1),                 # L = 1
    SensorConfig(b1=2, b2=2, threshold=1, acc_bits=1),        # theta = 1, smallest acc
    SensorConfig(b1=3, b2=3, threshold=5, acc_bits=3),        # smallest legal acc_bits for theta
    SensorConfig(b1=2, b2=3, input_bits=32, threshold=1000),  # 32-bit input
    SensorConfig(b1=5, b2=2, clocks_per_tick=3, threshold=7),
    SensorConfig(mode="ml", ml_bits=1, b1=2, b2=2),           # classic 1-bit spike camera
    SensorConfig(mode="ml", ml_bits=16, b1=2, b2=2, threshold=1, acc_bits=1),
    SensorConfig(mode="ml", b1=1, b2=1, clocks_per_tick=1, threshold=3, acc_bits=2, input_bits=1),
]

#: The ML camera with the most-significant-bit readout (SPEC sections 3-5) at the
#: same edges: its own list, so suites of parts without msb support are unchanged.
MSB_EDGE_CONFIGS = [
    SensorConfig(mode="ml", ml_readout="msb"),                # paper eq. 10 camera: 8 bits
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=1, b1=2, b2=2),
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=16, b1=2, b2=2, threshold=1, acc_bits=1),
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=3, b1=2, b2=2, threshold=5),   # saturates, L = 12
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=2, b1=1, b2=1, clocks_per_tick=1,
                 threshold=3, acc_bits=2, input_bits=1),      # L = 1, 1-bit input
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=5, b1=5, b2=2, clocks_per_tick=3,
                 threshold=7, input_bits=32),                 # odd clocks, 32-bit input
]

#: ML configurations with the msb readout (SPEC sections 3-4: the count's remainder stays in
#: the counter), at the edges of ml_bits (word width bit_length(ml_bits): 1, 2, 3, 4, 5 bits)
#: and of the clock structure. Kept apart from EDGE_CONFIGS so each package adds them where
#: it models the msb readout.
MSB_CONFIGS = [
    SensorConfig(mode="ml", ml_readout="msb"),                                     # paper: 8 bits, L = 240
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=1, b1=2, b2=2),              # 1-bit counter
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=16, b1=2, b2=2, threshold=1, acc_bits=1),
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=3, alpha=1, clocks_per_tick=1, threshold=2),  # L = 1
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=2, b1=3, b2=2, clocks_per_tick=5, threshold=7),
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=4, b1=1, b2=1, clocks_per_tick=7, threshold=1,
                 acc_bits=1, input_bits=1),                                        # L = 7, 1-bit input
    SensorConfig(mode="ml", ml_readout="msb", ml_bits=15, b1=5, b2=3, clocks_per_tick=3, input_bits=32,
                 threshold=1000),                                                  # 32-bit input, L = 21
]
