"""Registry of reconstruction methods and the one entry point :func:`reconstruct`.

``reconstruct(words, config, method)`` turns a (K, H, W) stream of readout
words into (K, H, W) float32 light, in the units of the scene (I = 1 is 42000
electrons per readout interval), one image per readout interval. Two kinds of
method, with bounded memory either way:

- TFP and TFI work along time, pixel by pixel: the stream is processed in
  blocks of pixels, and results do not depend on the block size;
- the learned methods (the project's network ``net`` and the paper's baselines,
  :data:`tespike.recon.learned.LEARNED`) are spatial:
  each image comes from the span of readouts their sizes fix around it, over
  whole tiles (:func:`tespike.recon.learning.infer.reconstruct_model`), with the shipped
  weights of the stream's sensor preset (:func:`tespike.recon.learned.weights_path`) or
  a weights file given (``weights``).
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np
import torch

from tespike.golden.config import SensorConfig
from tespike.golden.decode import check_word_dtype, check_words
from tespike.golden.errors import IllegalWordError, InputError, check_flag
from tespike.golden.io import images_array

from .decoding import as_word_tensor, decode_light, decode_spikes
from .learned import LEARNED_SUMMARIES
from .settings import DEFAULT_WINDOW, TRAINING_FREE, ReconSettings, check_known
from .tfi import tfi
from .tfp import tfp


def _tfp_block(words: torch.Tensor, config: SensorConfig, settings: ReconSettings,
               correction: tuple | None = None) -> torch.Tensor:
    """TFP of a (K, P) block; ``correction`` (dark, 1 / gain, dark law (atoms (Q, P), ceiling (P,))) of
    its P pixels: the window's own light under the pixels' dark law
    (:func:`tespike.recon.darklaw.law_light`), divided by the gain, floored at 0."""
    if correction is None:
        light = decode_light(words, config, estimator=settings.estimator, device=settings.device,
                             dtype=settings.torch_dtype)
        return tfp(light, settings.radius)
    from .darklaw import law_light
    _, inverse_gain, (atoms, ceiling) = correction
    light = decode_light(words, config, estimator=settings.estimator, device=settings.device)
    own, _ = law_light(light, config.spike_light, atoms, ceiling, settings.radius, settings.torch_dtype)
    return (own * inverse_gain.to(settings.device, own.dtype)).clamp_(min=0)


def _tfi_block(words: torch.Tensor, config: SensorConfig, settings: ReconSettings,
               correction: tuple | None = None) -> torch.Tensor:
    """TFI of a (K, P) block; ``correction`` (dark, 1 / gain, dark law (atoms (Q, P), ceiling (P,)) or
    None) of its P pixels: TFI of the pixels' own charge, re-coded as a pixel without dark current codes it
    (:func:`tespike.recon.calibration.dark_free_light`), so the intervals are those of the pixel's
    own light, not of its dark current; divided by the gain (TFI is linear in the light of fixed
    intervals). The own charge of a readout is its decoded spikes less its expected dark charge
    under the pixel's dark law at its window's light (:func:`tespike.recon.darklaw.law_light`),
    or less the mean dark rate where the calibration has no law."""
    if correction is None:
        light = decode_light(words, config, estimator=settings.estimator, device=settings.device,
                             dtype=settings.torch_dtype)
        return tfi(light, words != 0, config.spike_light, settings.radius, settings.search)
    from .calibration import dark_free_light
    dark, inverse_gain = (c.to(settings.device, torch.float64) for c in correction[:2])
    law = correction[2] if len(correction) > 2 else None
    if law is None:
        spikes = decode_spikes(words, config, estimator=settings.estimator, device=settings.device)
    else:
        from .darklaw import law_light
        decoded = decode_light(words, config, estimator=settings.estimator, device=settings.device)
        _, own = law_light(decoded, config.spike_light, *law, settings.radius)
        spikes, dark = own / config.spike_light, torch.zeros_like(dark)
    light = dark_free_light(spikes, dark, config.spike_light).to(settings.torch_dtype)
    return tfi(light, light > 0, config.spike_light, settings.radius, settings.search) * inverse_gain.to(light.dtype)


def _learned_frames(name: str) -> Callable:
    """The whole-stream function of learned method ``name``: the weights file given, else its shipped
    weights for the stream's preset."""
    def frames(words, config: SensorConfig, settings: ReconSettings, progress: bool,
               out: np.ndarray, weights=None, calibration=None) -> np.ndarray:
        from .learned import load_learned
        from .learning.infer import reconstruct_model
        model = load_learned(config, name, weights)
        images = reconstruct_model(model, words, config, device=settings.device, progress=progress, out=out,
                                   calibration=calibration)
        if not all(np.isfinite(images[k:k + 64]).all() for k in range(0, images.shape[0], 64)):
            source = "its shipped weights" if weights is None else f"weights {str(weights)!r}"
            raise InputError(f"{name} with {source} gives light that is not finite (weights of a scale "
                             "float32 overflows: not a trained network's)")
        return images
    frames.__name__ = f"_{name}_frames"
    return frames


@dataclasses.dataclass(frozen=True)
class Method:
    """A reconstruction method: a function of a (K, P) block of words -> (K, P) light
    (``block``, methods that work pixel by pixel along time), or of the whole
    (K, H, W) stream (``frames``, spatial methods that bound their memory themselves)."""

    name: str
    summary: str
    block: Callable[[torch.Tensor, SensorConfig, ReconSettings], torch.Tensor] | None
    options: tuple[str, ...]        # ReconSettings fields the method uses
    frames: Callable | None = None
    corrected_input: bool = False   # a calibration corrects its input (``block(..., correction)``), not its output
    law_input: bool = False         # so does a calibration with a dark law (TFP: its law-aware window light)


#: name -> reconstruction method (not golden.fastsim's simulation methods). The learned
#: ones ignore ``window``: they see the span their sizes fix (:func:`tespike.recon.learned.method_span`).
RECON_METHODS: dict[str, Method] = {
    "tfp": Method("tfp", TRAINING_FREE["tfp"], _tfp_block,
                  ("window", "estimator", "chunk_elements", "device", "dtype"), law_input=True),
    "tfi": Method("tfi", TRAINING_FREE["tfi"], _tfi_block,
                  ("window", "estimator", "search", "chunk_elements", "device", "dtype"), corrected_input=True),
    **{name: Method(name, summary, None, ("device",), frames=_learned_frames(name))
       for name, summary in LEARNED_SUMMARIES.items()},
}


def reconstruct(words, config: SensorConfig, method: str, *, window: int = DEFAULT_WINDOW,
                device: str = "cpu", progress: bool = False, out: np.ndarray | None = None,
                calibration=None, weights=None, **options) -> np.ndarray:
    """Stream words (K, H, W) -> reconstructed light, float32 (K, H, W), scene units.

    ``method`` is a key of :data:`RECON_METHODS`. ``window`` (odd, readouts) applies to TFP and
    TFI (the learned methods see the span their sizes fix); ``device`` (a torch device) to every
    method; further ``options``
    are fields of :class:`tespike.recon.settings.ReconSettings` the method uses
    (``estimator``, ``search`` for TFI, ``chunk_elements``, ``dtype``). Words are checked
    legal for ``config``; an unknown method or option is refused. ``out``: a
    float32 (K, H, W) array to fill (e.g. a memory map of the output file, so
    the images never need to fit in memory); it is returned. ``weights``: a
    learned method's weights file (None: the shipped ones; refused for TFP and TFI).
    ``calibration``: a :class:`tespike.recon.calibration.Calibration` of the sensor that recorded
    the stream; every method is then corrected for the pixels' dark rate and gain. With the
    calibration's dark law (``calibration.dark_law``): TFP as the window's light estimated under
    the law (:func:`tespike.recon.darklaw.law_light`; exactly TFP's windowed mean where the law
    holds no dark charge), TFI on the pixel's own charge, each readout less its expected dark
    charge under the law, re-coded as a pixel without dark current codes it, both divided by the
    gain. Without a law: TFP at its output, ``max(0, (x - dark) / gain)``
    (:func:`tespike.recon.calibration.correct`; exact, TFP being linear in the decoded light it
    averages); TFI on its input, the decoded spikes less the dark rate re-coded as a pixel without
    dark current codes them, its spike intervals then following the pixel's own light, not its
    dark current, and divided by the gain. The learned methods are corrected on every readout's
    decoded light, unfloored, their image floored at 0: ``(x - dark) / gain``
    (:func:`tespike.recon.learning.infer.frame`), and with a law, a readout the law puts in its upper
    tail less that charge instead (:func:`tespike.recon.learning.infer.law_input`). Each route was chosen by
    measurement (docs/reconstruction.md "Calibration").
    """
    config = SensorConfig.required(config, "reconstruct")
    check_flag(progress, "progress")                     # ('no' had shown a bar)
    check_known(method, RECON_METHODS)
    spec = RECON_METHODS[method]
    unknown = sorted(set(options) - set(spec.options))
    if unknown:
        raise InputError(f"option {unknown[0]!r} is not an option of method {method!r} "
                         f"(its options: {', '.join(spec.options)})")
    if weights is not None and spec.frames is None:
        raise InputError(f"weights apply to the learned methods, not to {method!r}")
    settings = ReconSettings(window=window, device=device, **options)
    if isinstance(words, torch.Tensor):
        shape = tuple(words.shape)
    else:
        words = np.asarray(words)
        shape = words.shape
        check_word_dtype(words.dtype)
    if len(shape) != 3:
        raise InputError(f"stream words shape {shape} must be (K, H, W)")
    K, H, W = shape
    if calibration is not None:
        from .calibration import check_matches
        check_matches(calibration, config, (H, W))
    out = images_array((K, H, W), out)
    if out.size == 0:
        return out
    try:
        return _dispatch(words, config, spec, settings, progress, out, weights, calibration)
    except IllegalWordError:                # found in a flattened block: name (readout, row, column)
        check_words(words.detach().cpu().numpy() if isinstance(words, torch.Tensor) else words, config)
        raise


def _dispatch(words, config, spec, settings, progress, out, weights, calibration) -> np.ndarray:
    """:func:`reconstruct` after its checks: the method's route (learned, corrected at its input or
    at its output, or raw)."""
    if spec.frames is not None:             # a learned method: corrected at its input
        return spec.frames(words, config, settings, progress, out, weights, calibration)
    if calibration is not None and (spec.corrected_input or (spec.law_input and calibration.dark_law is not None)):
        return _reconstruct_raw(words, config, spec, settings, progress, out, calibration)
    if calibration is not None:
        from .calibration import correct
        return correct(_reconstruct_raw(words, config, spec, settings, progress, out), calibration)
    return _reconstruct_raw(words, config, spec, settings, progress, out)


def _reconstruct_raw(words, config, spec, settings, progress, out, calibration=None) -> np.ndarray:
    """A training-free method's own output into ``out`` (K, H, W): uncorrected, or with ``calibration``
    given to a method that corrects its input, corrected there."""
    method = spec.name
    K, H, W = out.shape
    flat = words.reshape(K, H * W)
    out_flat = out.reshape(K, H * W)
    step = max(1, settings.block_elements() // K)
    starts = range(0, H * W, step)
    if calibration is not None:
        from .calibration import input_correction
        correction = [c.reshape(-1) for c in input_correction(calibration, dtype=torch.float64)]
        law = None if calibration.dark_law is None else calibration.law_tensors(settings.device)
    if progress:
        from tqdm import tqdm
        starts = tqdm(starts, desc=f"reconstruct {method}", unit="block")
    with torch.inference_mode():
        for start in starts:
            block = as_word_tensor(flat[:, start:start + step], settings.device)
            if calibration is None:
                result = spec.block(block, config, settings)
            else:
                pixels = slice(start, start + step)
                result = spec.block(block, config, settings, (*(c[pixels] for c in correction),
                                                              None if law is None else
                                                              (law[0][:, pixels], law[1][pixels])))
            out_flat[:, start:start + step] = result.to("cpu", torch.float32).numpy()
    return out


def missing_weights(method: str, config: SensorConfig, weights=None) -> str | None:
    """Why ``method`` cannot reconstruct streams of ``config`` with the weights file ``weights``
    (None: the shipped ones): the one-line refusal of its weights (missing, another method's,
    another sensor's), or None where it can."""
    check_known(method, RECON_METHODS)
    if RECON_METHODS[method].frames is None:
        return None
    from .learned import load_learned
    try:
        load_learned(config, method, weights)
    except InputError as exc:
        return str(exc)
    return None


def available_methods(configs, weights=None) -> tuple[str, ...]:
    """The methods of :data:`RECON_METHODS` that can reconstruct streams of every config given
    (TFP and TFI always; a learned method where its weights for each one are shipped, or given:
    ``weights`` maps (method, config) to a weights file)."""
    configs = list(configs) if not isinstance(configs, SensorConfig) else [configs]   # (one config: a TypeError)
    for config in configs:
        SensorConfig.required(config, "available_methods")
    if weights is not None and not isinstance(weights, dict):
        raise InputError(f"available_methods weights: must map (method, config) to a file, not {type(weights).__name__}")
    weights = weights or {}
    return tuple(m for m in RECON_METHODS if all(missing_weights(m, c, weights.get((m, c))) is None for c in configs))
