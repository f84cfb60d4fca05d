"""Readout words decoded in torch, by lookup table: light and spikes per readout, on any device.

Decoding uses exactly :mod:`tespike.golden.decode`: for each configuration (and
estimator) a table over every code a word of ``config.word_bits`` bits can
hold (at most 2^17) is filled once by calling :func:`tespike.golden.decode.decode_light`
and :func:`tespike.golden.decode.decode_spikes` on the legal codes; decoding a stream
is then one gather on the device. Codes outside SPEC section 4's word set
(:func:`tespike.golden.decode.legal_words`) are NaN in the table and refused, as
:func:`tespike.golden.decode.check_words` refuses them.
"""

from __future__ import annotations

import functools

import numpy as np
import torch

from tespike.golden.config import SensorConfig
from tespike.golden.decode import check_estimator, check_word_dtype, illegal_word, legal_words
from tespike.golden.decode import decode_light as golden_decode_light, decode_spikes as golden_decode_spikes
from tespike.golden.errors import InputError

from .settings import check_device


@functools.lru_cache(maxsize=64)
def code_tables(config: SensorConfig, estimator: str = "ratio") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lookup tables indexed by the code: light (scene units), spikes, legal (read-only numpy, over all
    2^word_bits codes; illegal entries NaN / False), from golden's decoder on its legal words.

    Built once per (configuration, estimator) and cached (configurations are
    immutable and hashable).
    """
    size = 1 << config.word_bits
    codes = legal_words(config)
    light = np.full(size, np.nan)
    spikes = np.full(size, np.nan)
    legal = np.zeros(size, bool)
    light[codes] = golden_decode_light(codes, config, estimator)
    spikes[codes] = golden_decode_spikes(codes, config, estimator)
    legal[codes] = True
    for table in (light, spikes, legal):
        table.setflags(write=False)
    return light, spikes, legal


def as_word_tensor(words, device: str | torch.device = "cpu") -> torch.Tensor:
    """Integer words (numpy of any integer dtype, or a tensor) -> int64 tensor on ``device``."""
    if isinstance(words, torch.Tensor):
        check_word_dtype(words.dtype)
        return words.to(device=device, dtype=torch.int64)
    words = np.asarray(words)
    check_word_dtype(words.dtype)
    if words.dtype == np.uint64 and words.size and int(words.max()) > np.iinfo(np.int64).max:
        raise InputError(f"readout word {int(words.max())} does not fit in int64")
    words = words.astype(np.int64, copy=not words.flags.writeable)  # (torch takes no read-only array: a
    return torch.from_numpy(words).to(device)                            # memory-mapped int64 stream is one)


def _refuse(w: torch.Tensor, bad: torch.Tensor, config: SensorConfig):
    index = tuple(int(i) for i in torch.nonzero(bad)[0])
    raise illegal_word(int(w[index]), index, config)


def check_light_dtype(dtype) -> torch.dtype:
    """``dtype``, a real torch floating type, refused in one line otherwise: an integer one had cut the
    decoded light to whole numbers (0.0625 -> 0), bool made every value True, and a numpy dtype or a
    name was torch's own TypeError."""
    if not (isinstance(dtype, torch.dtype) and dtype.is_floating_point):
        raise InputError(f"dtype = {dtype!r}: must be a torch floating type (torch.float64, torch.float32, ...)")
    return dtype


def _gather(table: np.ndarray, words, config: SensorConfig, device, dtype: torch.dtype) -> torch.Tensor:
    """table[words] on ``device``; any illegal word (NaN in the table) or one out of range is refused."""
    check_light_dtype(dtype)
    check_device(device)
    signed = (words.dtype.is_signed if isinstance(words, torch.Tensor)
              else np.asarray(words).dtype.kind == "i")
    w = as_word_tensor(words, device)
    if not w.numel():
        return torch.zeros(w.shape, dtype=dtype, device=device)
    if signed and int(w.min()) < 0:          # torch indexing would wrap a negative index
        _refuse(w, w < 0, config)
    values = torch.from_numpy(table.copy()).to(device=device, dtype=dtype)
    try:
        out = values[w]
    except IndexError:
        _refuse(w, w >= table.size, config)
    if bool(torch.isnan(out).any()):         # the table is NaN exactly at illegal codes
        _refuse(w, torch.isnan(out), config)
    return out


def decode_light(words, config: SensorConfig, *, estimator: str = "ratio",
                 device: str | torch.device = "cpu", dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """Words -> light per readout (scene units, 1.0 = 42000 electrons), equal to golden's.

    With ``dtype=torch.float32`` each value is golden's float64 value rounded once.
    """
    config = SensorConfig.required(config, "decode_light")
    return _gather(code_tables(config, check_estimator(estimator))[0], words, config, device, dtype)


def decode_spikes(words, config: SensorConfig, *, estimator: str = "ratio",
                  device: str | torch.device = "cpu", dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """Words -> spikes per readout interval, equal to :func:`tespike.golden.decode.decode_spikes`."""
    config = SensorConfig.required(config, "decode_spikes")
    return _gather(code_tables(config, check_estimator(estimator))[1], words, config, device, dtype)
