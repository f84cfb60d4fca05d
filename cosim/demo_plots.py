"""The demo's two pictures: the frame with the RTL crop marked, and the crop's reconstructions.

Both tone-map light with :func:`tespike.recon.mulaw.tone_map` (mu-law of light / the
sequence's peak, as every picture of the project) and save through
:func:`tespike.recon.pictures.save_figure`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_frame(light: np.ndarray, frame: int, crop: tuple[int, int, int], path: Path) -> None:
    """Tone-mapped ground truth of one frame with the RTL crop marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from tespike.recon.mulaw import MU, tone_map
    from tespike.recon.pictures import save_figure
    y, x, size = crop
    H, W = light.shape[1:]
    fig, axis = plt.subplots(figsize=(6.4, 6.4 * H / W + 0.5))
    axis.imshow(tone_map(light[frame], float(light.max())), cmap="gray", vmin=0, vmax=1,
                interpolation="nearest")
    axis.add_patch(Rectangle((x - 0.5, y - 0.5), size, size, fill=False, edgecolor="red", linewidth=1.5))
    axis.annotate("RTL crop", (x + size, y), color="red", fontsize=8, xytext=(3, -3),
                  textcoords="offset points", va="top")
    axis.set_xticks([])
    axis.set_yticks([])
    axis.set_title(f"ground truth, frame {frame}: μ-law (μ = {MU:g}) of light / sequence peak; "
                   f"RTL crop rows {y}..{y + size - 1}, columns {x}..{x + size - 1}", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def plot_rtl_crop(truth: np.ndarray, rtl_images: dict, golden_images: dict, peak: float,
                  frame: int, path: Path) -> None:
    """The crop at one frame: ground truth, each method on the RTL stream and on the golden
    full frame, and the |error| maps of the RTL's with a colour bar."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tespike.recon.mulaw import MU, tone_map
    from tespike.recon.pictures import ERROR_RANGE, save_figure
    methods = list(rtl_images)
    gt = tone_map(truth, peak)
    fig, axes = plt.subplots(3, 1 + len(methods), squeeze=False, figsize=(2.1 * (1 + len(methods)) + 0.6, 6.6))
    axes[0, 0].imshow(gt, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    axes[0, 0].set_title("ground truth", fontsize=8)
    axes[1, 0].axis("off")
    axes[2, 0].axis("off")
    shown = None
    for c, method in enumerate(methods, start=1):
        rtl = tone_map(rtl_images[method], peak)
        axes[0, c].imshow(rtl, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        axes[0, c].set_title(f"{method.upper()} on the RTL stream", fontsize=8)
        axes[1, c].imshow(tone_map(golden_images[method], peak), cmap="gray", vmin=0, vmax=1,
                          interpolation="nearest")
        axes[1, c].set_title(f"{method.upper()}, golden full frame", fontsize=8)
        shown = axes[2, c].imshow(np.abs(rtl - gt), cmap="magma", vmin=0, vmax=ERROR_RANGE,
                                  interpolation="nearest")
        axes[2, c].set_title(f"|error| {method.upper()} (RTL)", fontsize=8)
    for axis in axes.flat:
        axis.set_xticks([])
        axis.set_yticks([])
    fig.suptitle(f"RTL crop, frame {frame}: μ-law (μ = {MU:g}) of light / sequence peak", fontsize=9)
    fig.tight_layout()
    if shown is not None:
        bar = fig.colorbar(shown, cax=axes[2, 0].inset_axes([0.42, 0.05, 0.12, 0.9]))
        bar.set_label("|error| of μ-law images", fontsize=7)
        bar.ax.tick_params(labelsize=7)
    save_figure(fig, path)
