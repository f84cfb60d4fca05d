"""``tespike view``: look at a scene, stream, reconstruction or stimulus as tone-mapped PNGs.

Input by content: ``S.npz`` (a stream: words decoded to light per readout with
:func:`tespike.golden.decode.decode_light`), a float ``.npy`` (a scene ``I.npy`` or a
reconstruction ``R.npy``: light, 1.0 = design light), an integer ``.npy`` (a
stimulus ``E.npy``: electrons per readout interval, summed over its L clocks
with ``--config``, shown in design-light units). Tone mapping is the project's
(:func:`tespike.recon.mulaw.tone_map`): divide by the peak (default: the largest
value of the frames shown; give ``--peak`` to compare files on one scale),
clip to [0, 1], mu-law with mu = 5000. Writes a contact sheet (one PNG, frame
numbers as titles) or, with ``--each``, one grayscale PNG per frame at the
array's own resolution.
"""

from tespike.golden.decode import ESTIMATORS
from tespike.recon.mulaw import MU

HELP = "write tone-mapped PNGs (contact sheet or one per frame) of I.npy, S.npz, R.npy or E.npy"

#: Frames on a contact sheet unless --frames says otherwise (evenly spaced).
DEFAULT_SHEET_FRAMES = 12
#: Frames per row of a contact sheet unless --columns says otherwise.
DEFAULT_COLUMNS = 6
#: Most frames on one contact sheet (a panel each: 1700 frames took 50 s and made a PNG 69630
#: pixels tall; --each writes any number, one file a frame, in seconds).
MAX_SHEET_FRAMES = 240


def add_arguments(parser):
    parser.add_argument("--input", required=True, help="I.npy / R.npy (light), S.npz (stream) or E.npy "
                                                       "(stimulus, needs --config)")
    parser.add_argument("--out", required=True,
                        help="PNG contact sheet to write, or with --each the folder for frame_NNNN.png")
    parser.add_argument("--frames", help="frames to show: 'all', 'a:b' (b excluded) or a comma list "
                                         f"(default: {DEFAULT_SHEET_FRAMES} evenly spaced; --each: all)")
    parser.add_argument("--each", action="store_true", help="one PNG per frame instead of a contact sheet")
    parser.add_argument("--peak", type=float, help="light mapped to white (default: the frames' maximum)")
    parser.add_argument("--mu", type=float, default=MU, help=f"mu of the mu-law (default {MU:g})")
    parser.add_argument("--columns", type=int, help=f"frames per row of the sheet (default {DEFAULT_COLUMNS}; "
                                                    "not with --each)")
    parser.add_argument("--config", help="config of a stimulus E.npy (its clocks per readout L)")
    parser.add_argument("--estimator", choices=tuple(ESTIMATORS),
                        help="decoder estimator for a stream S.npz only (default ratio)")


def load_light(path, config_spec=None, estimator=None):
    """(light (K, H, W) float64, what) from any of the project's array files. ``config_spec`` is for
    a stimulus and ``estimator`` for a stream only: given for another kind of file, each is refused
    (it would be ignored)."""
    import numpy as np

    from tespike.golden.config import DESIGN_ELECTRONS, load_config
    from tespike.golden.decode import decode_light
    from tespike.golden.errors import InputError
    from tespike.golden.io import load_npy, load_scene, load_stimulus, load_stream

    from tespike.golden.paths import check_input_file
    path = check_input_file(path, "--input")        # exists, and is a regular file
    if path.suffix == ".npz":
        if config_spec is not None:
            raise InputError(f"--config applies to a stimulus E.npy only (the stream {str(path)!r} "
                             "carries its own configuration)")
        words, config = load_stream(path)
        if estimator is not None and not config.is_te:
            raise InputError(f"--estimator chooses among TE decoders; the ML stream {str(path)!r} has one "
                             "(leave --estimator out)")
        return decode_light(words, config, estimator or "ratio").astype(np.float64), f"stream ({config.describe()}), decoded"
    if estimator is not None:
        raise InputError(f"--estimator applies to a stream S.npz only ({str(path)!r} is not one)")
    header = load_npy(path, "--input", mmap_mode="r")
    if header.dtype.kind in "iu":
        if config_spec is None:
            raise InputError(f"--input {str(path)!r} holds integers (a stimulus E.npy): give --config "
                             "so its clocks per readout are known")
        config = load_config(config_spec)
        stimulus = load_stimulus(path, config)
        T, H, W = stimulus.shape
        L = config.clocks_per_readout
        per_readout = stimulus.reshape(T // L, L, H, W).sum(axis=1, dtype=np.int64)
        return per_readout / DESIGN_ELECTRONS, f"stimulus, electrons per readout / {DESIGN_ELECTRONS}"
    if config_spec is not None:
        raise InputError("--config applies to a stimulus E.npy only (a light file carries no config)")
    return load_scene(path, what="--input"), "light"


def pick_frames(spec, count, each):
    """Frame indices from ``--frames`` (see its help)."""
    import numpy as np

    from tespike.golden.errors import InputError
    if count == 0:
        raise InputError("--input has no frames (K = 0)")
    if spec is None:
        if each:
            return list(range(count))
        return sorted({int(i) for i in np.linspace(0, count - 1, min(count, DEFAULT_SHEET_FRAMES))})
    if spec == "all":
        return list(range(count))
    if ":" in spec:                   # (as score reads it: no Python slice, which clipped 0:99 and took -1:)
        from .common import frame_range
        return list(frame_range(spec, count))
    from .common import decimal
    try:
        frames = [decimal(x.strip()) for x in spec.split(",")]
    except ValueError:
        raise InputError(f"--frames {spec!r}: must be 'all', 'a:b' or a comma list of integers") from None
    bad = [f for f in frames if not 0 <= f < count]
    if bad:
        raise InputError(f"--frames {spec!r}: frame {bad[0]} outside 0..{count - 1}")
    if not frames:
        raise InputError(f"--frames {spec!r} selects no frame of 0..{count - 1}")
    twice = sorted({f for f in frames if frames.count(f) > 1})
    if twice:                         # (--each wrote one file for both and counted two)
        raise InputError(f"--frames {spec!r}: frame {twice[0]} is listed more than once")
    return frames


def run(args) -> int:
    import math
    import re
    from pathlib import Path

    from tespike.cosim.console import report
    from tespike.golden.errors import InputError
    from tespike.golden.paths import check_distinct, check_output_dir, check_outputs, written_through

    inputs = {"--input": args.input, "--config": args.config}
    if args.peak is not None and not (math.isfinite(args.peak) and args.peak > 0):
        raise InputError(f"--peak {args.peak}: must be a finite number > 0")
    if not (math.isfinite(args.mu) and args.mu > 0):
        raise InputError(f"--mu {args.mu}: must be a finite number > 0")
    if args.columns is not None and args.each:
        raise InputError("--columns applies to a contact sheet only (--each writes one PNG per frame)")
    if args.columns is not None and args.columns < 1:
        raise InputError(f"--columns {args.columns}: must be >= 1")
    out = Path(args.out)
    check_distinct(inputs, {"--out": args.out})     # (an input given as --out: the worse fault, named first)
    if args.each:
        if out.exists() and not out.is_dir():
            raise InputError(f"--out {str(out)!r} exists and is not a folder (--each writes a folder)")
        if out.suffix.lower() == ".png" and not out.is_dir():   # (a folder named so, made on purpose, is taken)
            raise InputError(f"--out {str(out)!r}: --each writes a folder of frame_NNNN.png files, not a .png "
                             "file (give a folder, or leave out --each for a contact sheet)")
        check_output_dir(args.out, "--out")         # (as typed: Path('') is '.', the folder of the inputs)
    elif out.suffix.lower() != ".png" and not written_through(args.out):   # (a device or FIFO takes any name)
        raise InputError(f"--out {str(out)!r}: a contact sheet is a .png file (or give --each and a folder)")
    elif not (out.parent if str(out.parent) else Path(".")).is_dir():
        raise InputError(f"--out {str(out)!r}: directory {str(out.parent)!r} does not exist")
    if not args.each:
        check_outputs({"--out": args.out}, inputs)
    light, what = load_light(args.input, args.config, args.estimator)
    frames = pick_frames(args.frames, light.shape[0], args.each)
    if not args.each and len(frames) > MAX_SHEET_FRAMES:
        raise InputError(f"--frames {args.frames!r} selects {len(frames)} frames; a contact sheet shows at most "
                         f"{MAX_SHEET_FRAMES} (select fewer, or write one PNG a frame with --each and a folder)")
    if args.each and out.is_dir():                  # (a frame file there may be an input, or a link to one)
        check_outputs({f"--out (frame {k})": out / f"frame_{k:04d}.png" for k in frames}, inputs)
        # the folder is replaced whole (atomic_folder): it may hold only frames this run writes again,
        # so that nothing else is removed and no folder mixes two runs' frames
        written = {f"frame_{k:04d}.png" for k in frames}
        stale = sorted(p.name for p in out.iterdir() if p.name not in written)
        other = [name for name in stale if not re.fullmatch(r"frame_\d{4,}\.png", name)]
        if other:
            raise InputError(f"--out {str(out)!r} holds {other[0]}, not a frame: --each makes the folder this "
                             "run's frames alone (give an empty or new folder)")
        if stale:
            raise InputError(f"--out {str(out)!r} holds {stale[0]}" + (f" and {len(stale) - 1} more frame file(s)"
                             if len(stale) > 1 else "") + " this run would not replace: it would mix two "
                             "runs' frames (give an empty folder, or remove them)")
    shown = light[frames]
    peak = args.peak if args.peak is not None else float(shown.max())
    if peak <= 0:
        raise InputError(f"--input {args.input!r}: every frame shown is 0 (give --peak to map it anyway)")

    from tespike.recon.mulaw import tone_map
    from tespike.recon.pictures import save_figure
    mapped = tone_map(shown, peak, args.mu)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if args.each:
        from tespike.golden.atomic import atomic_folder
        with atomic_folder(out) as folder:              # killed or failing: the previous frames stay whole
            for k, image in zip(frames, mapped):
                plt.imsave(folder / f"frame_{k:04d}.png", image, cmap="gray", vmin=0.0, vmax=1.0, format="png")
        report(args, f"wrote {len(frames)} frame(s) to {out}/frame_NNNN.png ({what}, peak {peak:.4g}, "
                     f"mu {args.mu:g})")
        return 0
    K, H, W = mapped.shape
    if args.columns is not None and args.columns > K:
        raise InputError(f"--columns {args.columns}: the sheet shows {K} frame(s); give at most {K}")
    columns = min(args.columns or DEFAULT_COLUMNS, K)
    rows = -(-K // columns)
    size = 2.2 / max(H, W)
    fig, axes = plt.subplots(rows, columns, squeeze=False,
                             figsize=(columns * W * size + 0.4, rows * (H * size + 0.25) + 0.5))
    for axis in axes.flat:
        axis.axis("off")
    for axis, k, image in zip(axes.flat, frames, mapped):
        axis.imshow(image, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
        axis.set_title(f"frame {k}", fontsize=8)
    fig.suptitle(f"{Path(args.input).name}: {what}; mu-law (mu = {args.mu:g}) of light / {peak:.4g}",
                 fontsize=8)
    fig.tight_layout()
    save_figure(fig, out)
    report(args, f"wrote {out}: {len(frames)} frame(s) of {Path(args.input).name} ({what})")
    return 0
