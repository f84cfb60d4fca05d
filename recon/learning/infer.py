"""Any learned method on whole streams: every readout gets an image, any frame size, bounded memory.

For key moment k the method sees readouts k - span/2 .. k + span/2; past
either end of the stream the first or last readout is repeated (so a stream
shorter than the span works, down to one readout), and the method is told
which readouts are such padding (``inside``). Frames are mirrored by
:data:`MIRROR_BORDER` pixels or more beyond every edge, to a multiple of the
method's pyramid factor (the convolutions' zero padding then meets scene
content, not a cliff: +0.9 dB on 16 x 16 crops, docs/network.md), and cut into
tiles whose cores are computed with :func:`tile_margin` pixels more on every
side: the receptive radius derived from the module itself
(:func:`module_radius`, :mod:`tespike.recon.reach`), rounded up to the pyramid
factor, so a tiled result equals the whole-frame one to float rounding
(``tests/test_recon_learning_infer.py``).

Tile size (:func:`tiles`): by default (``tile="auto"``) the core is
:data:`TILE_MARGINS` = 2 margins (:func:`default_tile`), so a tile computes
at most (2 + 2)^2 / 2^2 = 4 times its core's pixels and the peak memory is
that of a block of 4 margins square, whatever the frame size. Along an axis
no longer than core + margin the first block would already span the whole
axis, so that axis is not cut (same peak, less work); a frame within
core + margin on both axes runs whole. A tile given smaller than the margin
is accepted: the result is the same, only slower (each tile computes
(tile + 2 margin)^2 pixels for tile^2). ``tile=None`` runs the whole frame at
once. Which weights a module holds is the caller's (:func:`tespike.recon.learned.load_learned`).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import torch

from tespike.golden.config import SensorConfig
from tespike.golden.decode import word_stream
from tespike.golden.errors import InputError, is_count
from tespike.golden.io import images_array

from ..calibration import correct_input, input_correction
from ..decoding import decode_light
from ..reach import derive_radius
from ..settings import DEFAULT_WINDOW, check_window
from .span import key_span, span_inside


@functools.lru_cache(maxsize=64)
def module_radius(module_class: type, sizes) -> int:
    """Frame pixels an output pixel of ``module_class(sizes)`` can reach (an upper bound).

    Derived from the module built from ``sizes`` (on the meta device: no memory,
    no weights) by :func:`tespike.recon.reach.derive_radius`, so any change of a kernel,
    a level, an offset bound or a window shows in it.
    """
    with torch.device("meta"):
        model = module_class(sizes)
    return derive_radius(model)


#: Pixels of the frame mirrored beyond each edge before the network sees it (:func:`mirrored_index`).
MIRROR_BORDER = 8


def tile_margin(model: torch.nn.Module) -> int:
    """Overlap added on every side of a tile: the derived receptive radius rounded up to the pyramid factor."""
    f = model.sizes.pyramid_factor
    return -(-module_radius(type(model), model.sizes) // f) * f


#: The default tile core, in margins (:func:`default_tile`).
TILE_MARGINS = 2


def default_tile(model: torch.nn.Module) -> int:
    """The default tile core: :data:`TILE_MARGINS` margins (a multiple of the pyramid factor)."""
    return TILE_MARGINS * tile_margin(model)


def tiles(height: int, width: int, model: torch.nn.Module,
          tile: int | str | None = "auto") -> list[tuple[int, int, int, int]]:
    """Tile cores (y, x, h, w) covering the frame padded to the pyramid factor.

    ``tile``: the core's side (a multiple of the pyramid factor), ``"auto"`` for
    :func:`default_tile`, ``None`` for the whole frame. An axis no longer than
    core + margin is not cut (its first block would already span it).
    """
    f = model.sizes.pyramid_factor
    hp, wp = -(-height // f) * f, -(-width // f) * f
    if tile is None:
        return [(0, 0, hp, wp)]
    if tile == "auto":
        tile = default_tile(model)
    if type(tile) is not int or tile < f or tile % f:
        raise InputError(f"tile = {tile!r}: must be a multiple of the pyramid factor {f}, 'auto' or None")
    margin = tile_margin(model)
    ty = tile if hp > tile + margin else hp
    tx = tile if wp > tile + margin else wp
    return [(y, x, min(ty, hp - y), min(tx, wp - x)) for y in range(0, hp, ty) for x in range(0, wp, tx)]


def check_model(model) -> torch.nn.Module:
    """``model``, a learned method's module (a torch module with its ``sizes``), refused in one line
    otherwise (a name or a weights path had been an AttributeError: ``load_learned`` makes one)."""
    if not (isinstance(model, torch.nn.Module) and hasattr(model, "sizes")):
        raise InputError(f"model: must be a learned method's module (tespike.recon.learned.load_learned), "
                         f"not {type(model).__name__}")
    return model


def mirrored_index(length: int, factor: int) -> np.ndarray:
    """The rows (or columns) of the frame the network sees: the frame mirrored (``np.pad``
    "reflect") by :data:`MIRROR_BORDER` before its first row and by that or more after its
    last, to a multiple of the pyramid factor (a frame of one row repeats it); the frame
    itself starts at :data:`MIRROR_BORDER`.
    """
    if not (is_count(length, 1) and is_count(factor, 1)):     # (a factor of 0 was a ZeroDivisionError)
        raise InputError(f"mirrored_index: length {length!r} and factor {factor!r} must be integers >= 1")
    total = -(-(length + 2 * MIRROR_BORDER) // factor) * factor
    return np.pad(np.arange(length), (MIRROR_BORDER, total - length - MIRROR_BORDER), mode="reflect")


@dataclasses.dataclass(frozen=True)
class Block:
    """One tile as the network computes it: the frame rows and columns it reads (mirrored at the
    edges, with the tile margin), and where its core lands, in the frame and in its own result."""
    rows: np.ndarray
    cols: np.ndarray
    frame: tuple[slice, slice]
    result: tuple[slice, slice]


def blocks(height: int, width: int, model: torch.nn.Module, tile: int | str | None = None) -> list[Block]:
    """The blocks :func:`frame` computes for a ``height`` x ``width`` frame (see :func:`tiles`)."""
    row_index = mirrored_index(height, model.sizes.pyramid_factor)
    col_index = mirrored_index(width, model.sizes.pyramid_factor)
    top = left = MIRROR_BORDER
    hp, wp = len(row_index), len(col_index)
    cores = tiles(hp, wp, model, tile)
    margin = 0 if len(cores) == 1 else tile_margin(model)
    out = []
    for y, x, h, w in cores:
        ya, yb = max(y, top), min(y + h, top + height)          # the part of the core inside the frame
        xa, xb = max(x, left), min(x + w, left + width)
        if ya >= yb or xa >= xb:
            continue                                           # a core of mirrored border only
        y0, x0 = max(0, y - margin), max(0, x - margin)
        y1, x1 = min(hp, y + h + margin), min(wp, x + w + margin)
        out.append(Block(row_index[y0:y1], col_index[x0:x1], (slice(ya - top, yb - top), slice(xa - left, xb - left)),
                         (slice(ya - y0, yb - y0), slice(xa - x0, xb - x0))))
    return out


def frame(model: torch.nn.Module, words: np.ndarray, config: SensorConfig, key: int, *,
          tile: int | str | None = None, device: str = "cpu", correction=None,
          inputs: "LawInputs | None" = None) -> torch.Tensor:
    """The method's image (H, W) at readout ``key`` of the stream ``words`` (K, H, W).

    Only the readouts and pixels one tile needs are decoded at a time, so memory
    is bounded by the tile, not the frame. Readouts past either end repeat the
    first or last one; the frame is mirrored at its edges (:func:`mirrored_index`);
    with ``tile=None`` the whole mirrored frame is one tile (:func:`blocks`).
    ``correction``: (dark, 1 / gain) float32 (H, W) tensors on ``device`` (a sensor's
    calibration, :func:`tespike.recon.calibration.input_correction`); each readout's decoded light becomes
    ``(x - dark) / gain`` before the model sees it, negative where a readout caught less than
    the mean dark charge (not floored: a floor at 0 would add a bias of about the dark rate to
    every dim pixel, the light of one quantised readout being mostly 0 or one spike), and the
    image is floored at 0. ``inputs``: the stream's corrected input by readout indices
    (:class:`LawInputs`), read instead of decoding ``words`` (``correction`` then None); the image
    is floored at 0.
    """
    check_model(model)
    config = SensorConfig.required(config, "frame")
    words = word_stream(words)
    sizes = model.sizes
    K, H, W = words.shape
    times = key_span(K, key, sizes.span)
    inside = torch.from_numpy(span_inside(K, key, sizes.span))[None].to(device)
    out = torch.empty((H, W), dtype=torch.float32)
    for block in blocks(H, W, model, tile):
        if inputs is not None:
            seen = inputs(times, block.rows, block.cols).to(device)
        else:
            seen = decode_light(words[times[:, None, None], block.rows[None, :, None], block.cols[None, None, :]],
                                config, device=device, dtype=torch.float32)
        if correction is not None:
            pixels = (torch.from_numpy(block.rows)[:, None].to(device), torch.from_numpy(block.cols)[None].to(device))
            seen = correct_input(seen, tuple(c[pixels] for c in correction))
        image = model(seen[None], inside, config.spike_light)[0, 0][block.result].float().cpu()
        out[block.frame] = image if correction is None and inputs is None else image.clamp_min_(0)
    return out


def reconstruct_model(model: torch.nn.Module, words, config: SensorConfig, *, tile: int | str | None = "auto",
                      device: str = "cpu", progress: bool = False, out: np.ndarray | None = None,
                      calibration=None, inputs: "LawInputs | None" = None) -> np.ndarray:
    """Any learned method's module (in eval mode) on a whole stream: float32 light (K, H, W);
    ``calibration`` (checked by the caller against the stream) corrects its input: by the mean dark
    rate and the gain (:func:`frame`), or, where it carries a dark law, by the law (:class:`LawInputs`).
    ``inputs``: that stream's :class:`LawInputs` made by the caller (``keep=True``: the validation
    set scores every checkpoint on the same streams, and the law costs seconds a clip on a CPU)."""
    if isinstance(words, torch.Tensor):
        words = words.cpu().numpy()
    if not isinstance(words, np.ndarray):
        words = np.asarray(words)
    if words.ndim != 3:
        raise InputError(f"stream words shape {words.shape} must be (K, H, W)")
    K, H, W = words.shape
    out = images_array((K, H, W), out)
    if out.size == 0:
        return out
    model = model.to(device)
    if inputs is not None and (inputs.words is not words or inputs.calibration is not calibration
                               or inputs.config != config):
        raise ValueError("reconstruct_model: inputs were made for another stream or calibration")
    if inputs is None and calibration is not None and calibration.dark_law is not None:
        inputs = LawInputs(words, config, calibration, device=device)
    correction = input_correction(calibration, device) if inputs is None else None
    keys = range(K)
    if progress:
        from tqdm import tqdm
        keys = tqdm(keys, desc=f"reconstruct {type(model).__name__}", unit="frame")
    with torch.inference_mode():
        for k in keys:
            out[k] = frame(model, words, config, k, tile=tile, device=device, correction=correction,
                           inputs=inputs).numpy()
    return out


def law_input(words: np.ndarray, config: SensorConfig, calibration, window: int = DEFAULT_WINDOW,
              readouts: tuple[int, int] | None = None, device: str | torch.device = "cpu") -> torch.Tensor:
    """A learned method's input under a calibration with a dark law, (K, H, W) float32, unfloored:
    each readout's decoded light less the pixel's mean dark rate over the gain (the input the
    methods were trained with, :func:`frame`), except where the pixel's law puts the readout's dark
    charge in its upper tail (eq. 13's short dark intervals) at the light of its window of ``window``
    readouts: that share of the readout loses the charge itself (:func:`tespike.recon.darklaw.tail_free_light`),
    where the mean rate left most of it for the method to read as light. Exactly
    the mean-rate input where the law has no tail. Held-out eq. 13 PSNR-mu +0.7 to +1.3 dB, every eq.
    12 level within 0.06 dB (docs/reconstruction.md). The other readouts still lose the whole mean
    rate, which counts the tail they do not hold: with eq. 13 they read 90 e- low, which costs the
    moderately lit held-out scenes 4-5 dB and is what the shipped networks need on the buried pixels
    of the high-range ones (``benchmarks/dark_cost.py --rest below-tail``).

    ``readouts``: ``(start, stop)``, only those readouts (their windows read the stream around them,
    so the values are the whole stream's to float rounding); the float64 work runs in blocks of pixels,
    on ``device`` (the result stays there)."""
    from ..calibration import check_calibration
    from ..darklaw import BLOCK_ELEMENTS, tail_free_light
    config = SensorConfig.required(config, "law_input")
    calibration = check_calibration(calibration, "law_input's calibration")
    if calibration.dark_law is None:
        raise InputError("law_input's calibration holds no dark law (a calibration made from a dark stream has one)")
    check_window(window, "law_input window")
    words = word_stream(words)
    K, H, W = words.shape
    start, stop = (0, K) if readouts is None else readouts
    radius = window // 2
    first, last = max(0, start - radius), min(K, stop + radius)          # the windows' readouts
    flat = np.asarray(words[first:last]).reshape(last - first, H * W)
    atoms, ceiling = calibration.law_tensors(device)
    inverse_gain = torch.as_tensor(1.0 / calibration.gain, dtype=torch.float64, device=device).reshape(-1)
    mean_dark = torch.as_tensor(calibration.dark, dtype=torch.float64, device=device).reshape(-1)
    out = torch.empty((stop - start, H * W), dtype=torch.float32, device=device)
    step = max(1, BLOCK_ELEMENTS // max(1, last - first))   # pixels decoded in float64 at once (bounded memory)
    for s in range(0, H * W, step):
        pixels = slice(s, s + step)
        light = decode_light(flat[:, pixels], config, dtype=torch.float64, device=device)
        own = tail_free_light(light, config.spike_light, atoms[:, pixels], ceiling[pixels], radius,
                              mean_dark[pixels])
        out[:, pixels] = own[start - first:stop - first] * inverse_gain[pixels]
    return out.reshape(stop - start, H, W)


class LawInputs:
    """:func:`law_input` of a whole stream, read by readout indices as the key readouts move on:
    made :data:`LAW_BLOCK` readouts at a time, and a block dropped once the keys have passed it,
    so memory holds a few blocks of frames, not the stream (the images, too, may be a file);
    with ``keep`` every block made is kept, so the object can serve the stream again."""

    def __init__(self, words: np.ndarray, config: SensorConfig, calibration, window: int = DEFAULT_WINDOW,
                 block: int | None = None, device: str | torch.device = "cpu", keep: bool = False):
        self.words, self.config, self.calibration, self.window = words, config, calibration, window
        self.device = device
        self.block = LAW_BLOCK if block is None else block
        self.keep = keep
        self.blocks: dict[int, torch.Tensor] = {}

    def __call__(self, times: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> torch.Tensor:
        """The input of readouts ``times`` (any order, repeats allowed) at pixels ``rows`` x ``cols``
        (index arrays): (len(times), len(rows), len(cols))."""
        K = self.words.shape[0]
        needed = sorted(set((np.asarray(times) // self.block).tolist()))
        for b in [b for b in self.blocks if b < needed[0] and not self.keep]:
            del self.blocks[b]                          # keys only move on
        for b in needed:
            if b not in self.blocks:
                span = (b * self.block, min(K, (b + 1) * self.block))
                self.blocks[b] = law_input(self.words, self.config, self.calibration, self.window, span,
                                           self.device)
        index = (torch.as_tensor(np.array(rows), device=self.device)[:, None],
                 torch.as_tensor(np.array(cols), device=self.device)[None, :])
        return torch.stack([self.blocks[t // self.block][t % self.block][index] for t in np.asarray(times).tolist()])


#: Readouts of the law input made at once (:class:`LawInputs`).
LAW_BLOCK = 16
