"""Evaluation over a dataset store: one task per sequence x sensor x method (x tile).

The measures are those of :func:`tespike.recon.evaluate.evaluate` (paper Table 1:
PSNR-mu and SSIM-mu per frame after dividing by the sequence's peak, frames
whose window, or learned span, reaches past the sequence not scored
(:func:`tespike.recon.evaluate.scored_frames`), frame means averaged per
sequence, then over sequences), on the streams already in the store instead
of freshly simulated ones, and the output files are those of ``tespike
evaluate`` (:func:`tespike.recon.report.write_outputs` without its plot).

A frame that fits in one :data:`EVAL_TILE` is scored by one task with
:func:`tespike.recon.metrics.psnr_mu` / ``ssim_mu`` on whole frames, exactly as the
serial evaluation does. A larger frame is cut into tiles; each task
reconstructs its tile plus a halo of the SSIM window radius (TFP and TFI work
pixel by pixel along time, so the halo makes the tile exact) and
returns per-frame sums of squared mu-law error and of the SSIM map over its
own pixels; the driver adds them in tile order. Tiles depend only on the frame
size, and torch runs single-threaded in every task, so the numbers are the
same whatever the number of workers or the order in which tasks finish.

Run time per frame is not measured here (tasks share machines and cores with
each other): the ``ms / frame`` cells are left empty and ``results.csv`` has
``nan``; ``quality_vs_time.png`` is not written. Use ``tespike evaluate``
without ``--store`` or ``benchmarks/bench_recon.py`` for timing.
"""

from __future__ import annotations

import contextlib
import math
from typing import Sequence

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.decode import check_words
from tespike.golden.errors import IllegalWordError, InputError
from tespike.golden.io import check_frame_shape

from ..settings import DEFAULT_WINDOW
from .store import DatasetStore, open_array, reading, tiles

#: Largest frame (rows, cols) scored whole by one task; larger frames are tiled.
EVAL_TILE = (256, 256)
#: Readouts of float64 mu-law work held at once per tiled task.
METRIC_FRAMES = 16


def _halo() -> int:
    from tespike.recon.metrics import SSIM_SIGMA, SSIM_TRUNCATE
    return int(SSIM_TRUNCATE * SSIM_SIGMA + 0.5)


@contextlib.contextmanager
def _one_thread():
    """torch on one thread inside a task: no oversubscription, and reductions that do
    not depend on the machine's core count."""
    import torch
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@contextlib.contextmanager
def _about(url: str, sequence: str, sensor: str):
    """A refusal of what a task read (an illegal word, a light that is not finite) names the store,
    sequence and stream it came from: the task's own message knows only the array."""
    try:
        yield
    except InputError as exc:
        raise InputError(f"dataset store {url!r}, sequence {sequence!r}, stream {sensor!r}: {exc}") from None


def score_whole(url: str, sequence: str, sensor: str, method: str, window: int, device: str,
                peak: float, frames: tuple[int, int], middle: int, options: dict) -> dict:
    """Reconstruct and score whole frames (as :func:`tespike.recon.evaluate.evaluate`)."""
    from tespike.recon.methods import reconstruct
    from tespike.recon.metrics import psnr_mu, ssim_mu

    stream = open_array(url, f"{sequence}/streams/{sensor}")
    with reading(url, f"{sequence}/streams/{sensor}"):
        config = SensorConfig.from_json(stream.attrs["config"])
        words = stream[...]
    with _one_thread(), _about(url, sequence, sensor):
        images = reconstruct(words, config, method, window=window, device=device, **options)
        scored = slice(*frames)
        with reading(url, f"{sequence}/light"):
            truth = open_array(url, f"{sequence}/light")[scored]
        pred = images[scored]
        return {"psnr": psnr_mu(pred, truth, peak=peak), "ssim": ssim_mu(pred, truth, peak=peak),
                "strip": images[middle]}


def score_tile(url: str, sequence: str, sensor: str, method: str, window: int, device: str,
               peak: float, frames: tuple[int, int], middle: int, options: dict,
               rows: slice, cols: slice) -> dict:
    """One tile of a large frame: per scored frame, the sum of squared mu-law errors and
    of the SSIM map over the tile's own pixels (window centres), and its strip pixels."""
    import torch

    from tespike.recon.methods import reconstruct
    from tespike.recon.metrics import mu_law, normalise, ssim_map

    stream = open_array(url, f"{sequence}/streams/{sensor}")
    with reading(url, f"{sequence}/streams/{sensor}"):
        config = SensorConfig.from_json(stream.attrs["config"])
    K, H, W = stream.shape
    h = _halo()
    r0, r1, c0, c1 = rows.start, rows.stop, cols.start, cols.stop
    R0, R1, C0, C1 = max(0, r0 - h), min(H, r1 + h), max(0, c0 - h), min(W, c1 + h)
    # window centres of the whole frame's SSIM map that are this tile's pixels
    y0, y1, x0, x1 = max(r0, h), min(r1, H - h), max(c0, h), min(c1, W - h)
    core = (slice(None), slice(r0 - R0, r1 - R0), slice(c0 - C0, c1 - C0))
    centres = (slice(None), slice(y0 - R0 - h, y1 - R0 - h), slice(x0 - C0 - h, x1 - C0 - h))
    light = open_array(url, f"{sequence}/light")
    sse, ssum = [], []
    with _one_thread(), _about(url, sequence, sensor):
        with reading(url, f"{sequence}/streams/{sensor}"):
            words = stream[:, R0:R1, C0:C1]
        try:
            images = reconstruct(words, config, method, window=window, device=device, **options)
        except IllegalWordError:
            check_words(words, config, origin=(0, R0, C0))   # (the frame's index, not the tile's)
            raise
        for start in range(frames[0], frames[1], METRIC_FRAMES):
            stop = min(frames[1], start + METRIC_FRAMES)
            pred = torch.as_tensor(images[start:stop], dtype=torch.float64)
            with reading(url, f"{sequence}/light"):
                truth = torch.as_tensor(light[start:stop, R0:R1, C0:C1], dtype=torch.float64)
            p, g = normalise(pred, truth, peak)
            tp, tg = mu_law(p), mu_law(g)
            sse.append(((tp - tg) ** 2)[core].sum(dim=(1, 2)).numpy())
            if y1 > y0 and x1 > x0:
                ssum.append(ssim_map(tp, tg)[centres].sum(dim=(1, 2)).numpy())
            else:
                ssum.append(np.zeros(stop - start))
    return {"sse": np.concatenate(sse), "ssim_sum": np.concatenate(ssum),
            "strip": images[middle, r0 - R0:r1 - R0, c0 - C0:c1 - C0]}


def _combine(parts: list[dict], height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Tile sums (in tile order) -> per-frame PSNR-mu and SSIM-mu of the whole frames."""
    h = _halo()
    sse = np.sum([p["sse"] for p in parts], axis=0)
    ssum = np.sum([p["ssim_sum"] for p in parts], axis=0)
    with np.errstate(divide="ignore"):
        psnr = 10 * np.log10(1.0 / (sse / (height * width)))
    return psnr, ssum / ((height - 2 * h) * (width - 2 * h))


def evaluate_store(url: str, run, *, methods: Sequence[str] | None = None, window: int | None = None,
                   device: str = "cpu", tile: tuple[int, int] = EVAL_TILE,
                   options: dict[str, dict] | None = None, starting=None, progress=None):
    """Score every complete sequence x sensor x method of the store -> :class:`tespike.recon.evaluate.Evaluation`.

    ``window``: TFP's (None: the default, 9); given, at most 2 K - 1 of the shortest sequence's K.
    ``run`` runs ``dask.delayed`` tasks (:class:`tespike.cosim.dataset.cluster.Runner`);
    sensors are the store's configurations, in its order (they are the table's
    column groups); ``options`` as in :func:`tespike.recon.evaluate.evaluate`. ``starting()`` is called
    once every sequence, method and weights file is checked, before any task runs (a refusal comes
    before the command says what it will do). ``progress``: None, or ``progress(total)`` -> a function
    that wraps the iterable of finished tasks and reports as it is walked (``tespike evaluate
    --store`` passes a tqdm bar, :func:`tespike.cosim.console.bar`).
    """
    from tespike.recon.evaluate import check_method_options, learned_span
    from tespike.recon.settings import names

    if not callable(run):                               # (None had been a TypeError after the planning)
        raise InputError(f"run: must run the evaluation's tasks (a Runner), not {type(run).__name__}")
    tile = check_frame_shape(tile, "tile (rows, cols)")  # (0 had been a ZeroDivisionError)
    methods = None if methods is None else names(methods, "methods")   # ('tfp' had been the methods t, f, p)
    store = DatasetStore.open(url)
    sequences = store.sequences()
    infos = {s: store.check_sequence(s) for s in sequences}    # metadata consistent, no chunk file gone
    methods, window = _store_methods(store, infos, methods, window, device, tile)
    check_method_options(methods, options)
    learned = learned_span(methods)                      # frames scored as the serial evaluation scores them
    tasks, keys, plan = _score_tasks(store, infos, methods, window, device, tile, options, learned)
    if starting is not None:
        starting()
    outputs: list = [None] * len(tasks)
    for index, result in (iter if progress is None else progress(len(tasks)))(run(tasks)):
        outputs[index] = result
    by_cell: dict[tuple, list] = {}
    for key, result in zip(keys, outputs):
        by_cell.setdefault(key[:3], []).append((key[3], result))
    return _gathered(store, methods, window, learned, plan, by_cell)


def _store_methods(store, infos, methods, window, device, tile) -> tuple[tuple[str, ...], int]:
    """The methods and window of a store's evaluation, checked against its sequences (one line for
    the first refusal) -> (methods, window). By default every method that has weights for each
    sensor of the store and, where frames must be tiled, works pixel by pixel (a learned method sees
    far beyond the tiles' halo)."""
    from tespike.recon.evaluate import check_methods
    from tespike.recon.methods import RECON_METHODS, available_methods, missing_weights
    from tespike.recon.settings import ReconSettings, check_window_reach

    sequences = list(infos)
    tiled = [s for s in sequences if infos[s]["height"] > tile[0] or infos[s]["width"] > tile[1]]
    named = methods is not None
    methods = available_methods(store.configs.values()) if methods is None else tuple(methods)
    if tiled and not named:
        methods = tuple(m for m in methods if RECON_METHODS[m].block is not None)
    methods = check_methods(methods)
    spatial = [m for m in methods if RECON_METHODS[m].block is None]
    if tiled and spatial:
        raise InputError(f"method {spatial[0]!r} is spatial: sequence {tiled[0]!r} has frames larger than the "
                         f"{tile[0]} x {tile[1]} tiles of a store evaluation (evaluate it without --store)")
    for method in methods:                               # weights for every sensor, before any task runs
        for config in store.configs.values():
            reason = missing_weights(method, config)
            if reason is not None:
                raise InputError(reason)
    given, window = window is not None, DEFAULT_WINDOW if window is None else window
    ReconSettings(window=window, device=device)          # refuse a bad window or device here
    if not sequences:
        raise InputError(f"dataset store {store.url!r} holds no complete sequence")
    if given:                                            # (as the serial evaluation and reconstruct)
        shortest = min(sequences, key=lambda s: infos[s]["frames"])
        K = infos[shortest]["frames"]
        check_window_reach(window, K, f"the {K}-readout sequence {shortest!r}")
    return methods, window


def _score_tasks(store, infos, methods, window, device, tile, options, learned):
    """One ``dask.delayed`` scoring task per sequence x sensor x method (per tile where a frame is
    larger than ``tile``) -> (tasks, their (sequence, sensor, method, tile or None) keys, per sequence
    (H, W, peak, the strip's readout, the scored readouts))."""
    from dask import delayed

    from tespike.recon.evaluate import check_sequence_peak, scored_frames
    h = _halo()
    tasks, keys, plan = [], [], {}
    for sequence, info in infos.items():
        K, H, W = info["frames"], info["height"], info["width"]
        peak = check_sequence_peak(sequence, float(info["peak"]))
        stored = store.light_peak(sequence)
        if stored != peak:          # (a peak above the light's would lift every score: 550 dB)
            raise InputError(f"dataset store {store.url!r}: sequence {sequence!r} records peak {peak:g}, its "
                             f"light's maximum is {stored:g} (a damaged store: build it again with tespike dataset)")
        if min(H, W) < 2 * h + 1:
            raise InputError(f"sequence {sequence!r} is {H} x {W}: SSIM needs frames of at least "
                             f"{2 * h + 1} x {2 * h + 1} pixels")
        frames = scored_frames(K, window, learned)
        span = (frames.start, frames.stop)
        middle = (frames.start + frames.stop - 1) // 2
        whole = H <= tile[0] and W <= tile[1]
        plan[sequence] = (H, W, peak, middle, span)
        for sensor in store.configs:
            for method in methods:
                kwargs = dict((options or {}).get(method, {}))
                args = (store.url, sequence, sensor, method, window, device, peak, span, middle, kwargs)
                name = f"score-{sequence}-{sensor}-{method}"
                if whole:
                    tasks.append(delayed(score_whole, pure=False)(*args, dask_key_name=name))
                    keys.append((sequence, sensor, method, None))
                else:
                    for r, c, rows, cols in tiles(H, W, tile):
                        tasks.append(delayed(score_tile, pure=False)(*args, rows, cols,
                                                                     dask_key_name=f"{name}-{r}-{c}"))
                        keys.append((sequence, sensor, method, (rows, cols)))
    return tasks, keys, plan


def _gathered(store, methods, window, learned, plan, by_cell):
    """The tasks' results (``by_cell``: (sequence, sensor, method) -> [(tile or None, result)]) as one
    :class:`tespike.recon.evaluate.Evaluation`: a tiled frame's scores combined, its strip assembled."""
    from tespike.recon.evaluate import Evaluation, Measurement
    evaluation = Evaluation([], methods, tuple(store.configs), window, span=learned)
    for sequence, (H, W, peak, middle, span) in plan.items():
        with reading(store.url, f"{sequence}/light"):
            gt = np.asarray(store.array(sequence, "light")[middle])
        strip = {"gt": gt, "peak": peak, "frame": middle}
        for sensor in store.configs:
            for method in methods:
                parts = by_cell[sequence, sensor, method]
                if parts[0][0] is None:
                    result = parts[0][1]
                    psnr, ssim, image = result["psnr"], result["ssim"], result["strip"]
                else:
                    psnr, ssim = _combine([p for _, p in parts], H, W)
                    image = np.zeros((H, W), np.float32)
                    for (rows, cols), p in parts:
                        image[rows, cols] = p["strip"]
                evaluation.results.append(Measurement(sequence, sensor, method, float(np.mean(psnr)),
                                                 float(np.mean(ssim)), math.nan, int(span[1] - span[0])))
                strip[sensor, method] = image
        evaluation.strips[sequence] = strip
    return evaluation
