"""``tespike score``: every metric of the project on any reconstruction against its reference.

Both files are float ``.npy`` arrays (K, H, W) of light in scene units (SPEC's
I.npy and R.npy; a reconstruction made by another tool is welcome). Prints a
table (one row per frame, then the mean, then the sequence values of the
metrics that pool over time) or, with ``--json``, one JSON object. Refused with
one line: unreadable files, a non-float, non-(K, H, W) or non-finite array,
mismatched shapes, a negative or all-zero reference (or an all-zero reference
frame when PSNR-mu or SSIM-mu, which divide each frame by its peak, are asked
for), a bad ``--frames`` or ``--metrics``.
Negative estimated light is scored (every metric treats it as no light) with a
one-line warning on stderr.
"""

#: Values of the estimate checked at once (float64: 32 MB).
CHECK_VALUES = 1 << 22

HELP = "score a reconstruction R.npy against its reference I.npy: PSNR-mu, SSIM-mu, PU21-PSNR, HDR-VQM, FovVideoVDP"


def add_arguments(parser):
    from tespike.recon.score import METRIC_KEYS
    parser.add_argument("--reference", required=True, help="I.npy: float (K, H, W) reference light, scene units")
    parser.add_argument("--estimate", required=True, help="R.npy: float (K, H, W) reconstructed light, same shape")
    parser.add_argument("--frames", help="frames to score: 'a:b' (b excluded, either end may be left out); "
                                         "default all")
    parser.add_argument("--metrics", default=",".join(METRIC_KEYS),
                        help=f"comma list of metrics (default all: {','.join(METRIC_KEYS)})")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")


def load_estimate(path):
    """R.npy as a read-only map; refused unless a float (K, H, W) array."""
    from tespike.golden.errors import InputError
    from tespike.golden.io import load_npy
    estimate = load_npy(path, "estimate", mmap_mode="r")
    if estimate.dtype.kind != "f":
        raise InputError(f"estimate file {str(path)!r} holds {estimate.dtype}, not a float type "
                         "(light must be a float array)")
    if estimate.ndim != 3:
        raise InputError(f"estimate file {str(path)!r} holds shape {estimate.shape}: must be (K, H, W)")
    return estimate


def _text(value: float) -> str:
    import math
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.4f}"


def _json_number(value: float):
    import math
    return value if math.isfinite(value) else _text(value)


def run(args) -> int:
    import json
    import sys

    import numpy as np

    from tespike.golden.errors import InputError
    from tespike.golden.io import load_scene
    from tespike.recon.score import score

    from .common import metrics_argument

    if args.json and args.quiet:      # (the JSON is the whole output: quiet would drop it)
        raise InputError("--json prints the scores and --quiet prints nothing: give one of them")
    metrics = tuple(metrics_argument(args.metrics))   # (the library's refusal named neither the flag nor the name)
    reference = load_scene(args.reference, memory_map=True, what="reference")
    estimate = load_estimate(args.estimate)
    if estimate.shape != reference.shape:
        raise InputError(f"estimate file {str(args.estimate)!r} holds shape {estimate.shape}, reference file "
                         f"{str(args.reference)!r} {reference.shape}: they must be equal")
    from .common import frame_range

    frames = frame_range(args.frames, reference.shape[0])
    ref = reference[frames.start:frames.stop]          # memory maps: the metrics read them in bands
    est = estimate[frames.start:frames.stop]
    negative, lowest, peak = 0, 0.0, 0.0
    per_frame_peak = bool({"psnr_mu", "ssim_mu"} & set(metrics))
    step = max(1, CHECK_VALUES // max(1, ref[0].size))
    for k in range(0, len(frames), step):
        raw = np.asarray(est[k:k + step])
        e = raw.astype(np.float64, copy=False)
        if not np.isfinite(e).all():
            value = raw[~np.isfinite(e)][0]             # (in its own dtype: a long double's 1e4000 is finite)
            if np.isfinite(value):
                raise InputError(f"estimate file {str(args.estimate)!r} holds a value ({str(value)}) beyond "
                                 "float64's range, in which light is scored")
            raise InputError(f"estimate file {str(args.estimate)!r} holds a non-finite value "
                             f"({value}); light must be finite")
        negative += int((e < 0).sum())
        lowest = min(lowest, float(e.min()))
        frame_peaks = np.max(ref[k:k + step], axis=(1, 2))
        peak = max(peak, float(frame_peaks.max()))
        if per_frame_peak and not frame_peaks.all():
            frame = frames.start + k + int(np.argmin(frame_peaks > 0))
            raise InputError(f"reference frame {frame} is all zero: PSNR-mu and SSIM-mu divide each frame "
                             "by its peak (leave it out with --frames, or them with --metrics)")
    if not peak > 0:
        raise InputError(f"the reference is all zero in frames {frames.start}:{frames.stop}: "
                         "it has no peak to normalise by")
    if negative:              # one line, as a refusal is (Python's warning adds its source line)
        print(f"tespike score: warning: estimate {str(args.estimate)!r} holds {negative} negative light values "
              f"(lowest {lowest:g}); every metric scores them as no light", file=sys.stderr)
    result = score(est, ref, metrics=metrics)
    keys = [c.key for c in result.columns]
    if args.json:
        out = {
            "reference": str(args.reference), "estimate": str(args.estimate),
            "frames": [frames.start, frames.stop],
            "columns": {c.key: {"label": c.label, "higher_is_better": c.higher_is_better} for c in result.columns},
            "per_frame": {k: [_json_number(float(v)) for v in result.per_frame[k]] for k in keys},
            "mean": {k: _json_number(result.mean[k]) for k in keys},
            "sequence": {k: _json_number(v) for k, v in result.sequence.items()},
        }
        if not args.quiet:
            print(json.dumps(out, indent=2, allow_nan=False))
        return 0
    if args.quiet:
        return 0
    rows = [["frame"] + [c.label for c in result.columns]]
    for i, k in enumerate(frames):
        rows.append([str(k)] + [_text(float(result.per_frame[key][i])) for key in keys])
    rows.append(["mean"] + [_text(result.mean[key]) for key in keys])
    if result.sequence:
        rows.append(["sequence"] + [_text(result.sequence[key]) if key in result.sequence else "-"
                                    for key in keys])
    widths = [max(len(row[j]) for row in rows) for j in range(len(rows[0]))]
    for row in rows:
        print("  ".join(cell.rjust(w) for cell, w in zip(row, widths)))
    return 0
