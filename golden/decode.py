"""Readout words to spikes, electrons and light (SPEC section 5, paper eq. 3).

One decoder for the whole project: ``recon`` and ``cosim`` call these
functions; nothing else re-implements the formula.
"""

from __future__ import annotations

import functools

import numpy as np

from .config import SensorConfig
from .errors import IllegalWordError, InputError


#: Words checked at once by :func:`check_words` (bounds its int64 temporaries).
CHECK_CHUNK_WORDS = 1 << 22


def legal_words(config: SensorConfig) -> np.ndarray:
    """Every word of the configuration's word set (SPEC section 4), ascending int64 (read-only):
    TE counts 0..2^b1 - 1 and overflow words ``(1 << d) | m`` for m = 1..alpha; ML counts
    0..2^ml_bits - 1; msb words 0..ml_bits. The set is SPEC's contract, not what one pixel can
    reach: with one spike a pixel clock at most, counts above L and overflows before 2^b1 clocks
    never come from the sensor (docs/spec.md), yet decode as section 5 says."""
    return _legal_words(SensorConfig.required(config, "legal_words"))


@functools.lru_cache(maxsize=64)
def _legal_words(config: SensorConfig) -> np.ndarray:
    if config.is_te:
        counts = np.arange(config.p_max, dtype=np.int64)
        overflow = (1 << config.d) | np.arange(1, config.alpha + 1, dtype=np.int64)
        words = np.concatenate([counts, overflow])
    elif config.is_msb:
        words = np.arange(config.ml_bits + 1, dtype=np.int64)
    else:
        words = np.arange(config.ml_max + 1, dtype=np.int64)
    words.setflags(write=False)
    return words


@functools.lru_cache(maxsize=64)
def _legal_table(config: SensorConfig) -> np.ndarray:
    """legal[word] over every word of the configuration's word width."""
    table = np.zeros(1 << config.word_bits, bool)
    table[legal_words(config)] = True
    table.setflags(write=False)
    return table


def _word_ranges(words: np.ndarray) -> str:
    """'0..15, 17..31' for ascending words."""
    breaks = np.flatnonzero(np.diff(words) != 1)
    starts, ends = np.r_[words[:1], words[breaks + 1]], np.r_[words[breaks], words[-1:]]
    return ", ".join(f"{a}..{b}" if b > a else f"{a}" for a, b in zip(starts.tolist(), ends.tolist()))


def check_word_dtype(dtype) -> None:
    """Refuse readout words whose dtype (numpy's, or a torch tensor's, told by its name) is not an
    integer type, in one line."""
    try:
        dtype = np.dtype(dtype)
        integer = dtype.kind in "iu"
    except TypeError:                                  # a torch dtype: torch.int64, torch.uint8, ...
        integer = str(dtype).startswith(("torch.int", "torch.uint"))
    if not integer:
        raise InputError(f"readout words dtype {dtype} is not an integer type")


def word_stream(words, what: str = "words"):
    """``words`` as a (K, H, W) integer array of at least one readout (a memory map stays one, its values
    unread), refused in one line otherwise (a list had been an AttributeError, a 2-D array an unpacking
    error, no readout a ZeroDivisionError): the one check of the stream a reconstruction or a
    calibration reads before it decodes (which checks the values, :func:`check_words`)."""
    if not (hasattr(words, "ndim") and hasattr(words, "dtype")):
        words = np.asarray(words)
    if words.dtype.kind not in "iu":
        raise InputError(f"{what}: readout words dtype {words.dtype} is not an integer type")
    if words.ndim != 3 or min(words.shape) < 1:
        raise InputError(f"{what} shape {tuple(words.shape)} must be (K, H, W) with K, H, W >= 1")
    return words


def check_words(words: np.ndarray, config: SensorConfig, origin: tuple[int, ...] = ()) -> np.ndarray:
    """Refuse any word outside the configuration's word set (:func:`legal_words`).

    Checked in slices of about :data:`CHECK_CHUNK_WORDS` words along the first
    axis, so the memory it needs is bounded whatever the stream's size. ``origin``:
    where ``words`` starts in the array a refusal should name (a tile of a frame),
    added to the index it gives.
    """
    config = SensorConfig.required(config, "check_words")
    words = np.asarray(words)
    check_word_dtype(words.dtype)
    if not words.size:
        return words
    if words.ndim == 0:
        _check_word_block(words.reshape(1), config, lambda i: ())
        return words
    row = max(1, words[0].size)
    step = max(1, CHECK_CHUNK_WORDS // row)
    shift = tuple(origin) + (0,) * (words.ndim - len(origin))
    for start in range(0, words.shape[0], step):
        _check_word_block(words[start:start + step], config,
                          lambda index, start=start: tuple(i + o for i, o in zip((index[0] + start,) + index[1:],
                                                                                 shift)))
    return words


#: Illegal words inside a block's range that the fast check tests one by one (more: the table lookup).
FEW_HOLES = 4


@functools.lru_cache(maxsize=64)
def _holes(config: SensorConfig) -> np.ndarray:
    """The illegal words between the configuration's smallest and largest legal word (TE: 2^b1 ..
    2^d, the count past the counter and the overflow word of m = 0; none for ML)."""
    legal = legal_words(config)
    # From the lookup table, not np.setdiff1d: that imports numpy.ma (7 ms of every simulate).
    holes = np.flatnonzero(~_legal_table(config)[legal[0]:legal[-1] + 1]) + legal[0]
    holes.setflags(write=False)
    return holes


def _all_legal(words: np.ndarray, config: SensorConfig) -> bool:
    """Whether every word of the block is legal, from its smallest and largest (two reductions, a
    fraction of a millisecond for a 384 x 512 x 64 uint8 stream, where the table lookup took 60 ms)
    and a comparison per hole between them; False also where it cannot tell cheaply."""
    legal = legal_words(config)
    low, high = words.min(), words.max()
    if low < legal[0] or high > legal[-1]:
        return False
    holes = _holes(config)
    holes = holes[(holes >= low) & (holes <= high)]
    return holes.size <= FEW_HOLES and not any((words == hole).any() for hole in holes.tolist())


def _check_word_block(words: np.ndarray, config: SensorConfig, where) -> None:
    if _all_legal(words, config):
        return
    w = words.astype(np.int64)
    table = _legal_table(config)
    inside = (w >= 0) & (w < table.size)
    bad = ~inside
    bad[inside] = ~table[w[inside]]
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        raise illegal_word(int(words[index]), where(index), config)


def illegal_word(word: int, index: tuple, config: SensorConfig) -> IllegalWordError:
    """The refusal of a word that is no legal word of ``config`` (at ``index`` of its array): one wording
    wherever words are checked (here, and the torch decoder)."""
    return IllegalWordError(f"readout word {word} at index {index} is not a legal {config.mode.upper()} word "
                            f"for this configuration ({config.describe()}; its words are "
                            f"{_word_ranges(legal_words(config))})")


def _te_fields(words: np.ndarray, config: SensorConfig) -> tuple[np.ndarray, np.ndarray]:
    w = words.astype(np.int64)
    return (w >> config.d).astype(bool), w & ((1 << config.d) - 1)


def _spikes_ml(words, config):
    """ML count: the word; ML msb: 0 for word 0, else 2^(word - 1) (SPEC section 5, eq. 10)."""
    w = words.astype(np.int64)
    if config.is_msb:
        return np.where(w > 0, np.ldexp(1.0, np.maximum(w - 1, 0)), 0.0)
    return w.astype(np.float64)


def _spikes_ratio(words, config):
    """Default estimator: flag 0 -> b, flag 1 -> 2^b1 * alpha / m (paper eq. 3)."""
    if not config.is_te:
        return _spikes_ml(words, config)
    flag, value = _te_fields(words, config)
    m = np.where(flag, value, 1)
    return np.where(flag, config.p_max * config.alpha / m, value).astype(np.float64)


def _spikes_centred(words, config, spikes_at_overflow):
    """Flag 1 -> alpha * spikes_at_overflow / (m - 1/2), at most L spikes.

    The overflow clock lies somewhere in S_h cycle m, i.e. after (m - 1) F to
    m F clocks; for light that is not locked to the clock its position is
    close to uniform there, so the centre (m - 1/2) F is a better guess of the
    time to overflow than the end m F that the paper's alpha / m assumes (which
    biases every overflow code low, by a factor up to 2 at m = 1). A pixel fires
    at most once per clock, so no estimate exceeds L = F * alpha spikes.
    """
    if not config.is_te:
        return _spikes_ml(words, config)
    flag, value = _te_fields(words, config)
    m = np.where(flag, value, 1).astype(np.float64)
    estimate = np.minimum(config.alpha * spikes_at_overflow / (m - 0.5), config.clocks_per_readout)
    return np.where(flag, estimate, value).astype(np.float64)


def _spikes_midpoint(words, config):
    """Flag 1 -> 2^b1 * alpha / (m - 1/2), capped at L (overflow in the middle of S_h cycle m)."""
    return _spikes_centred(words, config, float(config.p_max))


def _spikes_residual(words, config):
    """Flag 1 -> (2^b1 - 1/2) * alpha / (m - 1/2), capped at L.

    As "midpoint", and also for the charge the pixel carried into the
    interval: with a residual uniform in [0, theta) the 2^b1-th threshold
    crossing needs on average (2^b1 - 1/2) thresholds of new charge, not 2^b1.
    """
    return _spikes_centred(words, config, config.p_max - 0.5)


#: Named decoding rules (SPEC section 5): words -> spikes per readout interval.
#: "ratio" is the paper's eq. 3 and the default everywhere; the others differ
#: only for TE overflow words (flag 1). See docs/dynamic-range.md for their
#: measured bias and spread.
ESTIMATORS = {"ratio": _spikes_ratio, "midpoint": _spikes_midpoint, "residual": _spikes_residual}


def decode_spikes(words: np.ndarray, config: SensorConfig, estimator: str = "ratio") -> np.ndarray:
    """Readout words -> float64 spikes per readout interval (SPEC section 5).

    ``estimator`` names the decoding rule; ``"ratio"`` is the paper's and the
    default. Other named rules are in :data:`ESTIMATORS`.
    """
    config = SensorConfig.required(config, "decode_spikes")
    return ESTIMATORS[check_estimator(estimator)](check_words(words, config), config)


def check_estimator(estimator) -> str:
    """``estimator``, a name of :data:`ESTIMATORS`, refused in one line otherwise (a list had been
    a dictionary's "unhashable type" traceback)."""
    if not (isinstance(estimator, str) and estimator in ESTIMATORS):
        raise InputError(f"unknown estimator {estimator!r} (known: {', '.join(ESTIMATORS)})")
    return estimator


def spikes_to_light(spikes: np.ndarray, config: SensorConfig) -> np.ndarray:
    """Spikes per readout -> light in scene units (1.0 = 42000 electrons per readout)."""
    config = SensorConfig.required(config, "spikes_to_light")
    try:
        spikes = np.asarray(spikes, np.float64)
    except (TypeError, ValueError):
        raise InputError(f"spikes: must be numbers, not {type(spikes).__name__}") from None
    return spikes * config.spike_light


def decode_light(words: np.ndarray, config: SensorConfig, estimator: str = "ratio") -> np.ndarray:
    """Readout words -> light per readout interval, in the units of ``I.npy``."""
    config = SensorConfig.required(config, "decode_light")
    return spikes_to_light(decode_spikes(words, config, estimator), config)
