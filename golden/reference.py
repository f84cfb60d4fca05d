"""The pixel update rule of SPEC section 3, written literally: one step per pixel clock.

This is the executable form of the specification, vectorised over pixels but
looping over clocks. It is slow on purpose (clarity over speed) and
is what the fast cycle-exact engine (:mod:`tespike.golden.sensor`) and the RTL are
checked against. Integer arithmetic in int64 cannot wrap: acc < 2^62 and
e < 2^32, so q = acc + e < 2^63.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .config import SensorConfig
from .errors import InputError
from .io import check_frame_shape, check_stimulus


@dataclasses.dataclass
class PixelState:
    """Carried state of an H x W array between chunks of pixel clocks."""

    clock: int              # global pixel clock t of the next input
    acc: np.ndarray         # int64 charge residual, never reset by readout
    sfc: np.ndarray         # int64 spike-firing counter (ML msb: keeps its remainder across readouts)
    ovf: np.ndarray         # bool overflow flag (TE)
    m: np.ndarray           # int64 latched CCC value (TE), 0 until overflow

    @classmethod
    def zeros(cls, shape: tuple[int, int]) -> "PixelState":
        """The power-up state of an H x W array (clock 0, everything cleared)."""
        shape = check_frame_shape(shape, "pixel state shape")
        return cls(0, np.zeros(shape, np.int64), np.zeros(shape, np.int64),
                   np.zeros(shape, bool), np.zeros(shape, np.int64))

    def copy(self) -> "PixelState":
        return PixelState(self.clock, self.acc.copy(), self.sfc.copy(), self.ovf.copy(), self.m.copy())


def msb_index(sfc: np.ndarray) -> np.ndarray:
    """bit_length of each count: 0 for 0, else j with 2^(j-1) <= sfc < 2^j (SPEC section 4)."""
    sfc = np.asarray(sfc, np.int64)
    # frexp is exact for integers below 2^53: sfc = f * 2^e with 0.5 <= f < 1, so e = bit_length
    return np.where(sfc > 0, np.frexp(sfc.astype(np.float64))[1], 0).astype(np.int64)


def msb_remainder(count: np.ndarray, word: np.ndarray) -> np.ndarray:
    """SPEC section 4, msb readout: the count left after the readout of ``word`` (its
    :func:`msb_index`): that power of two leaves, the remainder counts on."""
    return count - np.where(word > 0, np.left_shift(1, np.maximum(word - 1, 0)), 0)


def overflow_word(config: SensorConfig, m):
    """SPEC section 4: the TE word of an overflow latched in tick ``m`` (1..alpha), ``(1 << d) | m``."""
    return (1 << config.d) | m


def readout_word(config: SensorConfig, sfc: np.ndarray, ovf: np.ndarray, m: np.ndarray) -> np.ndarray:
    """SPEC section 4: TE :func:`overflow_word` on overflow else ``sfc``; ML ``sfc`` (count)
    or ``bit_length(sfc)`` (msb)."""
    if config.is_te:                                 # (np.where's array is new: no copy needed)
        return np.where(ovf, overflow_word(config, m), sfc).astype(np.int64, copy=False)
    if config.is_msb:
        return msb_index(sfc)
    return sfc.astype(np.int64)


def step_reference(config: SensorConfig, stimulus: np.ndarray,
                   state: PixelState | None = None) -> tuple[np.ndarray, PixelState]:
    """Run ``stimulus`` (T, H, W) clock by clock from ``state``.

    Returns the words of every readout interval that ends inside the chunk,
    shape (k, H, W), and the state after the last clock. Any T is accepted, so a
    run split anywhere gives the same stream.
    """
    config = SensorConfig.required(config, "step_reference")
    check_stimulus(stimulus, config, whole_readouts=False)   # integers (T, H, W) in 0..2^E - 1
    T, H, W = stimulus.shape
    if state is not None and not (isinstance(state, PixelState) and state.acc.shape == (H, W)):
        raise InputError(f"state: must be a PixelState of the stimulus's {H} x {W} pixels, not "
                         + (f"one of {state.acc.shape}" if isinstance(state, PixelState) else type(state).__name__))
    state = PixelState.zeros((H, W)) if state is None else state.copy()
    theta, acc_max = config.threshold, config.acc_max
    F, L = config.clocks_per_tick, config.clocks_per_readout
    words = []
    for i in range(T):
        t = state.clock + i
        q = state.acc + stimulus[i].astype(np.int64)
        spike = q >= theta
        state.acc = np.minimum(q - theta * spike, acc_max)
        if config.is_te:
            counting = spike & ~state.ovf
            state.sfc += counting
            overflow = counting & (state.sfc == config.p_max)
            state.ovf |= overflow
            state.m[overflow] = (t % L) // F + 1
        else:
            state.sfc = np.minimum(state.sfc + spike, config.ml_max)
        if t % L == L - 1:
            word = readout_word(config, state.sfc, state.ovf, state.m)
            words.append(word)
            if config.is_msb:       # that power of two leaves; the remainder counts on
                state.sfc = msb_remainder(state.sfc, word)
                continue
            state.sfc[:] = 0
            state.ovf[:] = False
            state.m[:] = 0
    state.clock += T
    stacked = np.stack(words) if words else np.zeros((0, H, W), np.int64)
    return stacked, state
