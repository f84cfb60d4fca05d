"""Per-pixel dark rate and gain from dark and flat streams, and the correction that uses them.

A camera team calibrates a sensor from two recordings by that sensor: one in
the dark (the lens capped) and one under uniform light of a known level (a flat
field). Per pixel, the mean decoded light over K readouts (SPEC section 5's
decoding, ``estimator="mean-decoded"``) is

    dark   = mean over the dark stream                    (light units per readout)
    gain   = (mean over the flat stream - dark) / flat_light

and a reconstruction ``x`` of that pixel is corrected to the light

    light  = max(0, (x - dark) / gain)                    (:func:`correct`)

which is exact for a method linear in the decoded light (TFP's windowed mean),
applied in one place (:func:`tespike.recon.methods.reconstruct`); TFI and the
learned methods are corrected at their input instead (:func:`dark_free_light`,
:func:`correct_input`). Light below 0 after subtracting the
dark rate is noise around darkness and is reported as 0 (the light is never
negative).

A mean cannot subtract a dark charge that changes from readout to readout (the
paper's eq. 13), so :func:`estimate` also keeps each pixel's **dark law**, the
quantiles of its dark spikes per readout (:func:`estimate_dark_law`,
:mod:`tespike.recon.darklaw`), and calibrated TFP and TFI estimate the light of a
window under it (:func:`tespike.recon.darklaw.law_light`): with no dark current in
the calibration that is exactly TFP's windowed mean; a calibration without a law
(``dark_law`` None: a format-1 file, or maps known exactly) corrects by the mean.

The mean decoded light is an unbiased rate estimate wherever the decoding
conserves spikes: the TE word without overflow (below ``2^b1`` spikes per
readout: for the paper's TE camera a flat below 2^4 x 175 / 42000 = 0.067),
ML counts, and the ML msb word (the remainder is carried) below the counter's
saturation. Record the flat below that level: :func:`estimate` reports the
share of overflow words in the flat (TE), where ``alpha / m`` decoding would bias
the gain. A pixel whose estimated gain is below :data:`MIN_GAIN` (a dead pixel,
or a flat too dim for the readouts taken) is given :data:`MIN_GAIN` and counted
in ``floored``.

File ``C.npz`` (``np.savez``): ``dark`` (H, W) float64, light units (1 = 42000
electrons) per readout; ``gain`` (H, W) float64, relative to the nominal pixel;
``config``: the JSON text of the full :class:`tespike.golden.config.SensorConfig` the
streams were recorded with; ``dark_readouts``, ``flat_readouts`` (int), ``flat_light``
(float), ``estimator`` (text), ``floored`` (int), ``overflow_share`` (float);
``dark_law`` (Q, H, W) float32, decoded dark spikes per readout at the quantile levels
(i + 0.5) / Q (Q = 0: no law); ``dark_tail`` (float), the largest dark readout over its
pixel's mean atom; and ``format`` = :data:`FORMAT`. A file of :data:`FORMAT_MEAN_ONLY`
(no law) is read as a calibration without a law. A calibration applies only to streams of the same
configuration and frame size (:func:`check_matches`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.decode import decode_light, decode_spikes, legal_words, word_stream
from tespike.golden.errors import InputError, is_positive_number

#: How every calibration file's maps were estimated (its "estimator" member; not a decoding rule of
#: tespike.golden.decode.ESTIMATORS).
CALIBRATION_ESTIMATOR = "mean-decoded"
#: Version tag of the file format.
FORMAT = "tespike-calibration-2"
#: The previous format: the same maps without the dark law (read, corrected by the mean dark rate).
FORMAT_MEAN_ONLY = "tespike-calibration-1"
#: Smallest gain a pixel is given (a pixel below it is dead or was not lit enough).
MIN_GAIN = 0.05
#: Median gain above which :func:`estimate` refuses the flat's stated light (no sensor's
#: non-uniformity comes near it: the flat was recorded at another light than the one stated).
MAX_GAIN = 1 / MIN_GAIN
#: Share of a flat's words at the sensor's top code (:func:`saturated_words`) from which
#: :func:`estimate` refuses it: most of its pixels saw light beyond the sensor's range.
MAX_SATURATED_SHARE = 0.5
#: Share of a TE flat's words that are overflow words from which :func:`estimate` refuses it, where its
#: stated light is above the overflow level (:func:`flat_ceiling`): there the
#: mean decoding no longer conserves spikes (a flat at 0.1 to 0.9, all overflow words, read gains 2 to
#: 43 % low and every calibrated image up to 1.7 times too bright).
MAX_OVERFLOW_SHARE = 0.5
#: Readouts decoded at once (bounds memory to this many float64 frames).
CHUNK_READOUTS = 32
#: Readouts of each calibration stream (dark and flat) the project records: the evaluation's
#: sensors (:mod:`tespike.recon.evaluate`) and the training clips' dark laws
#: (:func:`tespike.recon.engine.clips.sensor_calibration`) are calibrated alike.
CALIBRATION_READOUTS = 256


@dataclasses.dataclass(frozen=True)
class Calibration:
    """Per-pixel dark rate and gain of one sensor, for one configuration."""

    dark: np.ndarray            # (H, W) float64, light units per readout
    gain: np.ndarray            # (H, W) float64
    config: SensorConfig
    dark_readouts: int
    flat_readouts: int
    flat_light: float
    estimator: str = CALIBRATION_ESTIMATOR
    floored: int = 0
    overflow_share: float = 0.0
    #: (Q, H, W) float32, decoded dark spikes per readout at Q quantile levels (recon.darklaw), or
    #: None: only the mean dark rate is known (TFP and TFI then subtract it)
    dark_law: np.ndarray | None = None
    #: the reach of the law's tail: the largest dark readout over its pixel's mean atom (recon.darklaw)
    dark_tail: float = 0.0

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.dark.shape)

    def law_tensors(self, device="cpu"):
        """The dark law on ``device``: its atoms (Q, H W) float32 and the tail's ceiling (H W) float64,
        ``dark_tail`` x each pixel's mean atom, spikes per readout; built here once for calibrated
        TFP and TFI (:func:`tespike.recon.methods.reconstruct`) and the learned methods' input."""
        import torch
        atoms = torch.as_tensor(np.asarray(self.dark_law, np.float32), device=device)
        atoms = atoms.reshape(self.dark_law.shape[0], -1)
        return atoms, self.dark_tail * atoms.to(torch.float64).mean(0)


def mean_decoded_light(words, config: SensorConfig) -> np.ndarray:
    """Per-pixel mean decoded light (scene units) over the readouts of ``words`` (K, H, W)."""
    config = SensorConfig.required(config, "mean_decoded_light")
    words = word_stream(words)
    K = words.shape[0]
    total = np.zeros(words.shape[1:])
    for start in range(0, K, CHUNK_READOUTS):
        total += decode_spikes(np.asarray(words[start:start + CHUNK_READOUTS]), config).sum(axis=0)
    return total * (config.spike_light / K)


def flat_ceiling(config: SensorConfig) -> float:
    """Light (scene units) below which a nominal pixel's mean decoded light conserves spikes: TE below
    its overflow (2^b1 spikes a readout: 0.067 for the paper's camera), ML below its counter's top
    (or one spike a clock, whichever comes first)."""
    from tespike.golden.config import DESIGN_ELECTRONS
    config = SensorConfig.required(config, "flat_ceiling")
    if config.is_te:
        spikes = config.p_max
    elif config.is_msb:             # (the msb word holds counts below 2^(ml_bits - 1) whole)
        spikes = min(1 << (config.ml_bits - 1), config.clocks_per_readout)
    else:
        spikes = min(config.ml_max, config.clocks_per_readout)
    return spikes * config.threshold / DESIGN_ELECTRONS


def saturated_words(config: SensorConfig) -> np.ndarray:
    """The words the sensor gives where every clock's input saturates (2^E - 1 electrons a clock:
    any light far enough above its range), over two readouts from an empty accumulator (a carried
    charge can change the count by one): a pixel reading only these words shows no light level."""
    from tespike.golden.sensor import PixelArrayModel
    config = SensorConfig.required(config, "saturated_words")
    clocks = 2 * config.clocks_per_readout
    words = PixelArrayModel(config, (1, 1)).feed(np.full((clocks, 1, 1), config.input_max, np.int64))
    return np.unique(words)


def saturated_share(words, top: np.ndarray) -> float:
    """Share of ``words`` (K, H, W) that are among ``top`` (the configuration's :func:`saturated_words`)."""
    words = word_stream(words)
    count = sum(int(np.count_nonzero(np.isin(np.asarray(words[s:s + CHUNK_READOUTS]), top)))
                for s in range(0, words.shape[0], CHUNK_READOUTS))
    return count / words.size


def overflow_share(words, config: SensorConfig) -> float:
    """Share of TE overflow words in ``words`` (0 for ML)."""
    config = SensorConfig.required(config, "overflow_share")
    words = word_stream(words)
    if not config.is_te:
        return 0.0
    flag = 1 << config.d                    # the overflow flag bit above the TE payload (golden's rule)
    count = sum(int(np.count_nonzero(np.asarray(words[s:s + CHUNK_READOUTS]) >= flag))
                for s in range(0, words.shape[0], CHUNK_READOUTS))
    return count / words.size


def estimate_dark_law(words, config: SensorConfig, atoms: int | None = None) -> tuple[np.ndarray, float]:
    """Per-pixel dark law of the dark stream ``words`` (K, H, W): (atoms, H, W) float32 quantiles of
    its decoded spikes per readout (:func:`tespike.recon.darklaw.law_atoms`), rows at a time, and the
    reach of its tail: the largest dark readout over its pixel's mean atom, over the frame (0 where
    no pixel saw dark charge)."""
    from .darklaw import LAW_ATOMS, check_atoms, law_atoms
    config = SensorConfig.required(config, "estimate_dark_law")
    words = word_stream(words, "dark stream")
    atoms = LAW_ATOMS if atoms is None else check_atoms(atoms)
    K, H, W = words.shape
    out = np.empty((atoms, H, W), np.float32)
    reach = 0.0
    rows = max(1, (CHUNK_READOUTS * H * W) // max(1, K * W))     # the memory of CHUNK_READOUTS frames
    for top in range(0, H, rows):
        spikes = decode_spikes(np.asarray(words[:, top:top + rows]), config)
        law = out[:, top:top + rows] = law_atoms(spikes, atoms)
        mean = law.astype(np.float64).mean(0)
        if (mean > 0).any():
            reach = max(reach, float((spikes.max(0)[mean > 0] / mean[mean > 0]).max()))
    return out, reach


def estimate(dark_words, flat_words, config: SensorConfig, flat_light: float) -> Calibration:
    """Dark stream (K_d, H, W) and flat stream (K_f, H, W) of one sensor, the flat's light
    (scene units) -> :class:`Calibration`."""
    config = SensorConfig.required(config, "estimate")
    if not is_positive_number(flat_light):
        raise InputError(f"flat light {flat_light!r}: must be a finite number > 0 (1 = design light)")
    dark_words, flat_words = word_stream(dark_words, "dark stream"), word_stream(flat_words, "flat stream")
    if dark_words.shape[1:] != flat_words.shape[1:]:
        raise InputError(f"dark stream frames {dark_words.shape[1:]} and flat stream frames "
                         f"{flat_words.shape[1:]} differ: both must come from the same sensor")
    top_words = saturated_words(config)              # (2 L clocks of the cycle-exact model: made once)
    top = ", ".join(map(str, top_words.tolist()))
    saturated = saturated_share(dark_words, top_words)
    if saturated >= MAX_SATURATED_SHARE:
        raise InputError(f"the dark stream is saturated: {100 * saturated:.1f} % of its words are the sensor's "
                         f"top code ({top}): its dark current alone is beyond the sensor's range, and no "
                         "calibration recovers light under it")
    flat_read = mean_decoded_light(flat_words, config)
    saturated = saturated_share(flat_words, top_words)
    if saturated >= MAX_SATURATED_SHARE and config.is_msb:
        # (the msb word of the top code is also the ordinary reading of any count of 2^(ml_bits - 1) or
        # more: a flat below the ceiling reads it most of the time and still conserves spikes)
        saturated = saturated if float(np.median(flat_read)) >= 0.97 * flat_ceiling(config) else 0.0
    if saturated >= MAX_SATURATED_SHARE:
        raise InputError(f"the flat stream is saturated: {100 * saturated:.1f} % of its words are the sensor's "
                         f"top code ({top}: what any light above its range gives), so its light cannot be "
                         f"measured; record the flat at a lower light (below {flat_ceiling(config):.3g}, "
                         "where the mean decoding conserves spikes)")
    overflowing = overflow_share(flat_words, config)
    if overflowing >= MAX_OVERFLOW_SHARE and flat_light > flat_ceiling(config):
        # (only a flat whose own light passes the overflow: under strong dark current a flat below it
        # may overflow half the time from the dark charge, which the dark stream shares)
        raise InputError(f"flat light {flat_light:g} is above the TE overflow level ({flat_ceiling(config):.3g}): "
                         f"{100 * overflowing:.1f} % of the flat's words are overflow words, whose mean decoding "
                         "does not conserve spikes; record the flat at a lower light")
    dark = mean_decoded_light(dark_words, config)
    shown = flat_read - dark
    if float(np.median(shown)) > MAX_GAIN * float(flat_light):
        raise InputError(f"flat light {flat_light:g}: the flat stream's pixels read {float(np.median(shown)):.4g} "
                         f"(median, less the dark), above {MAX_GAIN:g} times it: state the light the flat "
                         "was recorded at (1 = design light)")
    if float(np.median(shown)) < MIN_GAIN * float(flat_light):
        raise InputError(f"flat light {flat_light:g}: the flat stream's pixels read {float(np.median(shown)):.4g} "
                         f"(median, less the dark), below {MIN_GAIN:g} times it: no brighter than the dark "
                         "stream for that light (is the flat light stated above the one it was recorded at? were the "
                         "dark and flat streams swapped, or the flat recorded without light?)")
    raw_gain = shown / float(flat_light)
    floored = int(np.count_nonzero(raw_gain < MIN_GAIN))
    return Calibration(dark, np.maximum(raw_gain, MIN_GAIN), config, int(dark_words.shape[0]),
                       int(flat_words.shape[0]), float(flat_light), CALIBRATION_ESTIMATOR, floored,
                       overflowing, *estimate_dark_law(dark_words, config))


def save_calibration(path: str | Path, calibration: Calibration) -> None:
    """Write ``C.npz`` (atomically: a temporary file beside it, then renamed)."""
    from tespike.golden.io import atomic_output
    c = check_calibration(calibration)
    with atomic_output(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez(handle, dark=c.dark, gain=c.gain, config=np.array(c.config.to_json()),
                     dark_readouts=np.int64(c.dark_readouts), flat_readouts=np.int64(c.flat_readouts),
                     flat_light=np.float64(c.flat_light), estimator=np.array(c.estimator),
                     floored=np.int64(c.floored), overflow_share=np.float64(c.overflow_share),
                     dark_law=(np.zeros((0, *c.shape), np.float32) if c.dark_law is None
                               else np.asarray(c.dark_law, np.float32)),
                     dark_tail=np.float64(c.dark_tail),
                     format=np.array(FORMAT))


def load_calibration(path: str | Path) -> Calibration:
    """Read ``C.npz``, or one line naming the file and what is wrong."""
    from tespike.golden.io import config_member, open_npz, text_member
    shown = str(path)
    with open_npz(path, "calibration", "written by 'tespike calibrate'") as npz:
        keys = ("dark", "gain", "config", "dark_readouts", "flat_readouts", "flat_light", "estimator",
                "floored", "overflow_share", "format")
        missing = [k for k in keys if k not in npz.files]
        if missing:
            raise InputError(f"calibration file {shown!r} lacks {', '.join(missing)} "
                             "(write it with 'tespike calibrate')")
        values = {k: npz[k] for k in keys}
        for key in ("format", "estimator"):             # text, bytes read as UTF-8 (as 'config' is)
            values[key] = text_member(values[key], f"calibration file {shown!r}", key)
        version = values["format"]
        if version not in (FORMAT, FORMAT_MEAN_ONLY):
            raise InputError(f"calibration file {shown!r} has format {version!r}, not {FORMAT!r} "
                             f"(or {FORMAT_MEAN_ONLY!r})")
        if version == FORMAT and "dark_law" not in npz.files:
            raise InputError(f"calibration file {shown!r} lacks dark_law (write it with 'tespike calibrate')")
        law_keys = ("dark_law", "dark_tail")
        extra = [k for k in npz.files if k not in keys and (version != FORMAT or k not in law_keys)]
        if extra and extra[0] in law_keys:      # (dropped without a word: the law of a format-1 file)
            raise InputError(f"calibration file {shown!r} has format {version!r} and holds {extra[0]!r}, which "
                             f"only format {FORMAT!r} has")
        if extra:
            raise InputError(f"calibration file {shown!r} holds {extra[0]!r} beside the members 'tespike calibrate' "
                             "writes")
        law = np.asarray(npz["dark_law"]) if version == FORMAT else None
        stored = np.asarray(npz["dark_tail"]) if version == FORMAT and "dark_tail" in npz.files else None
        tail = float(stored) if stored is not None and stored.ndim == 0 and stored.dtype.kind in "iuf" \
            else math.nan                   # (a string, an array or a complex number: refused below)
        if version == FORMAT and not (np.isfinite(tail) and tail >= 0):
            raise InputError(f"calibration file {shown!r}: dark_tail must be a finite number >= 0 "
                             "(write it with 'tespike calibrate')")
    config = config_member(values["config"], f"calibration file {shown!r}")
    for name in ("dark", "gain"):
        if values[name].dtype.kind != "f":
            raise InputError(f"calibration file {shown!r}: {name} must be a float (H, W) map, not {values[name].dtype}")
    dark, gain = np.asarray(values["dark"], np.float64), np.asarray(values["gain"], np.float64)
    if dark.ndim != 2 or dark.shape != gain.shape or not (np.isfinite(dark).all() and np.isfinite(gain).all()):
        raise InputError(f"calibration file {shown!r}: dark and gain must be finite (H, W) maps of one shape")
    numbers = _checked_numbers(shown, values, dark.size)
    # what 'tespike calibrate' can write: dark a mean of decoded light, gain (flat - dark) / flat light
    # floored at MIN_GAIN; no word decodes above ``top``
    top = float(decode_light(legal_words(config), config).max())
    if (dark < 0).any() or (dark > top).any():
        raise InputError(f"calibration file {shown!r}: dark must lie in [0, {top:g}] (a mean of decoded light; "
                         f"found {float(dark.min()):g} to {float(dark.max()):g})")
    high = top / numbers["flat_light"] * (1 + 1e-9)
    if (gain < MIN_GAIN).any() or (gain > high).any():
        raise InputError(f"calibration file {shown!r}: gain must lie in [{MIN_GAIN:g}, {high:.6g}] (the flat's "
                         f"light over {numbers['flat_light']:g}, floored at {MIN_GAIN:g}; found "
                         f"{float(gain.min()):g} to {float(gain.max()):g})")
    if float(np.median(gain)) > MAX_GAIN:       # (as estimate refuses it: a flat read far above its stated light)
        raise InputError(f"calibration file {shown!r}: its median gain {float(np.median(gain)):g} is above "
                         f"{MAX_GAIN:g}, which 'tespike calibrate' never writes")
    if law is not None:
        if law.dtype != np.float32 or law.ndim != 3 or law.shape[1:] != dark.shape \
                or not np.isfinite(law).all() or (law < 0).any():
            raise InputError(f"calibration file {shown!r}: dark_law must be float32 (Q, H, W) of the maps' "
                             f"frame size, finite and >= 0, not {law.dtype} {law.shape}")
        most = float(decode_spikes(legal_words(config), config).max())     # decoded spikes of one readout
        if law.size and float(law.max()) > most * (1 + 1e-6):
            raise InputError(f"calibration file {shown!r}: dark_law must lie in [0, {most:g}] (decoded dark "
                             f"spikes of one readout; found up to {float(law.max()):g})")
        if law.shape[0] == 1 or (np.diff(law, axis=0) < 0).any():
            raise InputError(f"calibration file {shown!r}: dark_law must hold Q >= 2 quantiles of each pixel "
                             f"in ascending order (or none), not {law.shape[0]}"
                             + ("" if law.shape[0] == 1 else " out of order"))
        law = law if law.shape[0] else None
    return Calibration(dark, gain, config, numbers["dark_readouts"], numbers["flat_readouts"],
                       numbers["flat_light"], CALIBRATION_ESTIMATOR, numbers["floored"], numbers["overflow_share"],
                       law, tail if law is not None else 0.0)


def _checked_numbers(shown: str, values: dict, pixels: int) -> dict:
    """The calibration file's scalars, each refused in one line naming it where 'tespike calibrate'
    could not have written it."""
    out = {}
    for name, kind, ok, rule in (("dark_readouts", int, lambda v: v >= 1, "an integer >= 1"),
                                 ("flat_readouts", int, lambda v: v >= 1, "an integer >= 1"),
                                 ("flat_light", float, lambda v: math.isfinite(v) and v > 0, "a finite number > 0"),
                                 ("floored", int, lambda v: 0 <= v <= pixels, f"an integer in 0..{pixels}"),
                                 ("overflow_share", float, lambda v: 0 <= v <= 1, "a number in [0, 1]")):
        value = values[name]
        good = value.ndim == 0 and value.dtype.kind in ("iu" if kind is int else "iuf")
        if good:
            out[name] = kind(value)
            good = ok(out[name])
        if not good:                            # (the value itself, not numpy's array(...) of it)
            held = repr(value.item()) if value.ndim == 0 and value.dtype.kind != "O" else \
                f"a {value.dtype} array of shape {value.shape}"
            raise InputError(f"calibration file {shown!r}: {name} must be {rule}, not {held}")
    if str(values["estimator"]) != CALIBRATION_ESTIMATOR:
        raise InputError(f"calibration file {shown!r}: estimator {str(values['estimator'])!r} unknown "
                         f"(tespike calibrate writes {CALIBRATION_ESTIMATOR!r})")
    return out


def check_calibration(calibration, name: str = "the calibration") -> Calibration:
    """``calibration`` where it is a :class:`Calibration`, else one line naming ``name`` (a path given
    where :func:`load_calibration`'s result belongs had been an AttributeError)."""
    if not isinstance(calibration, Calibration):
        raise InputError(f"{name} must be a Calibration (tespike.recon.calibration.load_calibration(path)), "
                         f"not {type(calibration).__name__}")
    return calibration


def check_matches(calibration: Calibration, config: SensorConfig, shape: tuple[int, int],
                  what: str = "the stream", name: str = "the calibration") -> None:
    """Refuse, in one line naming both (``name``: the calibration, e.g. its file), a calibration made
    for another configuration or frame size than ``what``, or what is no :class:`Calibration` (a path
    given where :func:`load_calibration`'s result belongs)."""
    check_calibration(calibration, name)
    difference = calibration.config.differences_text(config, "the calibration", what)
    if difference is not None:
        raise InputError(f"{name} is for another sensor configuration than {what}: {difference}")
    if tuple(shape) != calibration.shape:
        raise InputError(f"{name} holds maps of {calibration.shape[0]} x {calibration.shape[1]} pixels, "
                         f"{what} frames of {shape[0]} x {shape[1]}")


def correct(images: np.ndarray, calibration: Calibration) -> np.ndarray:
    """Reconstructed light (K, H, W) -> ``max(0, (x - dark) / gain)`` per pixel, in place
    where ``images`` is a writable float array (a memory-mapped R.npy stays on disk)."""
    calibration = check_calibration(calibration)
    out = images if isinstance(images, np.ndarray) and images.flags.writeable and \
        images.dtype.kind == "f" else np.array(images, np.float32)
    if out.ndim != 3 or out.shape[1:] != calibration.shape:
        raise InputError(f"images of shape {out.shape}: the calibration corrects (K, {calibration.shape[0]}, "
                         f"{calibration.shape[1]}) frames")
    dark, inverse = calibration.dark.astype(out.dtype), (1.0 / calibration.gain).astype(out.dtype)
    for k in range(out.shape[0]):           # one frame at a time: bounded memory
        frame = out[k]
        frame -= dark
        frame *= inverse
        np.maximum(frame, 0, out=frame)
    return out


def input_correction(calibration: Calibration | None, device: str = "cpu", dtype=None):
    """``calibration`` as the (dark, 1 / gain) tensors (H, W) of :func:`correct_input` on ``device``,
    float32 unless ``dtype`` says otherwise (None for None): TFI and the learned methods are
    corrected at their input, where the dark rate is subtracted from light the method has not
    yet shaped (docs/reconstruction.md)."""
    if calibration is None:
        return None
    check_calibration(calibration, "input_correction's calibration")
    import torch
    dtype = torch.float32 if dtype is None else dtype
    return (torch.as_tensor(calibration.dark, dtype=dtype, device=device),
            torch.as_tensor(1.0 / calibration.gain, dtype=dtype, device=device))


def correct_input(light, correction):
    """Each readout's decoded light ``x`` corrected to ``(x - dark) / gain``, ``correction`` being
    (dark, 1 / gain) broadcast against ``light`` (:func:`input_correction`): not floored, for the
    learned methods (a floor at 0 would add about the dark rate to every dim pixel) and their
    training clips alike. TFI re-spikes it instead (:func:`dark_free_light`)."""
    dark, inverse_gain = correction
    return (light - dark) * inverse_gain


def dark_free_light(spikes, dark, spike_light: float):
    """Decoded spikes per readout (K, ...) of pixels whose dark rate is ``dark`` (light units per
    readout, broadcast against ``spikes[0]``) -> the light (K, ...) of the pixels' own charge, coded
    as a pixel without dark current codes it, for TFI (float64 throughout).

    The net charge since the stream start, ``sum(spikes) - k dark``, is the pixel's own charge
    (its residual carried, as the pixel carries its own); a readout fires where its high-water
    mark (floored at 0) passes a new whole spike, and then carries all the net charge gained
    since the previous firing readout. A readout that caught less than the dark rate leaves a
    deficit that later readouts must fill: flooring each readout at 0 instead (``max(0, x - dark)``)
    subtracted the dark rate only at readouts that fire, so a pixel firing every few readouts on
    its dark charge kept most of that charge as light. Conserved: the light over the stream is
    the high-water mark at the last firing readout, within one spike of the net charge unless the
    net charge ends below its peak. With ``dark`` 0 the light is each readout's own (to rounding)."""
    import torch
    if not is_positive_number(spike_light):             # (0 had given zeros, NaN NaNs)
        raise InputError(f"spike light {spike_light!r}: must be a finite number > 0")
    spikes = torch.as_tensor(spikes, dtype=torch.float64)
    if spikes.dim() < 1:                                 # (an IndexError)
        raise InputError("spikes: must be readouts (K, ...), not one number")
    dark_spikes = torch.as_tensor(dark, dtype=torch.float64, device=spikes.device) / spike_light
    from .tfi import running_max
    high = running_max(torch.cumsum(spikes - dark_spikes, 0)).clamp_(min=0)
    whole = torch.floor(high)
    fires = whole > torch.cat([torch.zeros_like(whole[:1]), whole[:-1]])
    reached = running_max(torch.where(fires, high, 0.0))     # the mark at the last firing readout
    before = torch.cat([torch.zeros_like(reached[:1]), reached[:-1]])
    return torch.where(fires, high - before, 0.0) * spike_light


def calibration_summary(calibration: Calibration) -> str:
    """One line: maps, readouts, mean dark (electrons per readout), gain spread, floored pixels."""
    c = check_calibration(calibration, "calibration_summary's calibration")
    from tespike.golden.config import DESIGN_ELECTRONS
    return (f"{c.shape[0]} x {c.shape[1]} pixels from {c.dark_readouts} dark and {c.flat_readouts} flat "
            f"readouts (flat light {c.flat_light:g}): dark {DESIGN_ELECTRONS * c.dark.mean():.0f} e-/readout "
            f"mean ({DESIGN_ELECTRONS * np.median(c.dark):.0f} median), gain {c.gain.mean():.4f} +- "
            f"{c.gain.std():.4f}, {c.floored} pixels floored at gain {MIN_GAIN}, "
            f"{100 * c.overflow_share:.2f} % overflow words in the flat"
            + ("" if c.dark_law is None else f", dark law of {c.dark_law.shape[0]} quantiles "
               f"(tail to {c.dark_tail:.1f} x the mean)"))
