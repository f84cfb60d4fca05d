"""Readout words to spikes, electrons and light (SPEC section 5, paper eq. 3).

One decoder for the whole project: ``recon`` and ``cosim`` call these
functions; nothing else re-implements the formula.
"""

from __future__ import annotations

import numpy as np

from .config import DESIGN_ELECTRONS, SensorConfig
from .errors import InputError


def check_words(words: np.ndarray, config: SensorConfig) -> np.ndarray:
    """Refuse any word that the configured sensor cannot emit (SPEC section 4)."""
    words = np.asarray(words)
    if words.dtype.kind not in "iu":
        raise InputError(f"readout words dtype {words.dtype} is not an integer type")
    if not words.size:
        return words
    w = words.astype(np.int64)
    if config.is_te:
        flag = w >> config.d
        value = w & ((1 << config.d) - 1)
        bad = (w < 0) | (flag > 1) | ((flag == 0) & (value >= config.p_max)) | \
              ((flag == 1) & ((value < 1) | (value > config.alpha)))
    else:
        bad = (w < 0) | (w > config.ml_max)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"readout word {int(w[index])} at index {index} is not a legal "
                         f"{config.mode.upper()} word for this configuration ({config})")
    return words


def _te_fields(words: np.ndarray, config: SensorConfig) -> tuple[np.ndarray, np.ndarray]:
    w = words.astype(np.int64)
    return (w >> config.d).astype(bool), w & ((1 << config.d) - 1)


def _spikes_ratio(words, config):
    """Default estimator: flag 0 -> b, flag 1 -> 2^b1 * alpha / m (paper eq. 3)."""
    if not config.is_te:
        return words.astype(np.float64)
    flag, value = _te_fields(words, config)
    m = np.where(flag, value, 1)
    return np.where(flag, config.p_max * config.alpha / m, value).astype(np.float64)


ESTIMATORS = {"ratio": _spikes_ratio}


def decode_spikes(words: np.ndarray, config: SensorConfig, estimator: str = "ratio") -> np.ndarray:
    """Readout words -> float64 spikes per readout interval (SPEC section 5).

    ``estimator`` names the decoding rule; ``"ratio"`` is the paper's and the
    default. Other named rules are in :data:`ESTIMATORS`.
    """
    try:
        rule = ESTIMATORS[estimator]
    except KeyError:
        raise InputError(f"unknown estimator {estimator!r} (known: {', '.join(ESTIMATORS)})") from None
    return rule(check_words(words, config), config)


def spikes_to_light(spikes: np.ndarray, config: SensorConfig) -> np.ndarray:
    """Spikes per readout -> light in scene units (1.0 = 42000 electrons per readout)."""
    return np.asarray(spikes, np.float64) * (config.threshold / DESIGN_ELECTRONS)


def decode_light(words: np.ndarray, config: SensorConfig, estimator: str = "ratio") -> np.ndarray:
    """Readout words -> light per readout interval, in the units of ``I.npy``."""
    return spikes_to_light(decode_spikes(words, config, estimator), config)
