"""Building a dataset: HDR frame folders and built-in scenes -> light and sensor streams in a store.

Per sequence, the work is a small Dask graph (every task idempotent: the
same inputs write the same bytes, so a retry after a lost worker is harmless):

1. HDR folders: one task per ``chunk_frames`` frames reads them (grayscale,
   :func:`tespike.recon.scenes.to_gray`) and returns their maximum; the sequence peak is
   the maximum of those. Then one task per chunk reads the frames again and
   writes ``light = frame * (1 / peak)`` as float32, exactly what
   :func:`tespike.recon.scenes.load_hdr_sequence` returns (paper appendix A.2.2),
   without ever holding the whole sequence. A built-in scene is one task
   (:func:`tespike.recon.scenes.make_scene`, public seed 0, as ``tespike scene``).
2. Per sensor configuration, one task per simulation tile (:data:`TILE`) runs
   :class:`tespike.golden.fastsim.SceneSimulator` (the code of ``tespike simulate``)
   readout after readout over the whole sequence, reading and writing
   ``chunk_frames`` readouts at a time: the simulator carries charge across
   readouts, so time is walked in order inside a task and tiles are the
   parallel axis. Memory per task: chunk_frames x tile.
3. Each array, then the sequence, is marked complete (the sequence last).

Seeds: tile (r, c) of sequence s with configuration C draws from
:func:`tespike.recon.dataset.tile_seed` (root seed, SHA-256 of s and C's JSON, r, c),
never from the order of completion, and the simulator's error budget counts the
whole sequence's pixel-readouts (as ``tespike simulate`` on the whole frame), so
a frame that fits in one tile gives exactly ``simulate_scene(config, light,
seed=default_rng(tile_seed(seed, s, C, 0, 0)))`` (a tile is below the size
:func:`tespike.golden.fastsim.simulate_scene` splits into stripes).
Tiles run one simulator each in their task (Dask workers are the parallel
axis), never ``simulate_scene``'s forked workers.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from tespike.golden.atomic import NO_ROOM, folder_held
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count
from tespike.golden.paths import path_text
from tespike.recon.dataset.store import (CHUNK_FRAMES, TILE, DatasetStore, check_name, mark_complete,
                                 open_array, tile_seed, tiles)


@dataclasses.dataclass(frozen=True)
class Source:
    """One sequence of the dataset: an HDR frame folder or a built-in scene."""

    name: str
    shape: tuple[int, int, int]
    description: str                        # the sequence's ``source`` attribute
    frames: tuple[str, ...] = ()            # HDR frame files, in order
    weights: str = "rec709"                 # grayscale weights of HDR frames
    scene: tuple[str, int, int, int] | None = None     # built-in: (name, frames, height, width)
    digest: str = ""                        # HDR frames: :func:`frames_digest` of their files


def read_gray(path: str, weights: str) -> np.ndarray:
    """One HDR frame -> float32 grayscale (H, W), as :func:`tespike.recon.scenes.load_hdr_sequence` reads it."""
    from tespike.recon.scenes import read_image, to_gray
    return to_gray(read_image(path), weights, what=f"frame {path!r}").astype(np.float32)


def frames_digest(paths: Sequence[Path]) -> str:
    """A digest of a sequence's frame files, names and bytes in order (BLAKE2b, 128 bits): a
    resumed store compares it with the one its sequence was made from, so frames rewritten in
    place between two runs are not mixed into one dataset (names, sizes and shapes can all stay)."""
    import hashlib
    digest = hashlib.blake2b(digest_size=16)
    for path in paths:
        digest.update(Path(path).name.encode() + b"\0")
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        digest.update(b"\0")
    return digest.hexdigest()


def hdr_sources(folder: str | Path, *, weights: str = "rec709", max_frames: int | None = None) -> list[Source]:
    """Every sub-folder of ``folder`` holding HDR frames is one sequence, named after it.

    Hidden sub-folders (``.name``) are skipped; a sub-folder without frames is
    refused, as is a folder without sub-folders, and a sequence whose frames' headers give
    different sizes (before anything is planned); the first frame of each is decoded.
    """
    from tespike.recon.scenes.color import check_weights
    from tespike.recon.scenes.hdr_io import FRAME_SUFFIXES, list_frames, sequence_size

    folder = Path(path_text(folder, "--hdr"))
    check_weights(weights)
    if max_frames is not None and not is_count(max_frames, 1):   # (-1 had dropped the last frame, True kept one)
        raise InputError(f"max_frames = {max_frames!r}: must be an integer >= 1")
    if not folder.is_dir():
        raise InputError(f"--hdr {str(folder)!r} does not exist or is not a folder")
    entries = list(folder.iterdir())
    subfolders = sorted(p for p in entries if p.is_dir() and not p.name.startswith("."))
    if not subfolders:
        raise InputError(f"--hdr {str(folder)!r} holds no sub-folders (one folder of frames per sequence)")
    loose = sorted(p.name for p in entries if p.suffix.lower() in FRAME_SUFFIXES)
    if loose:                       # (read as no sequence: it was dropped without a word)
        raise InputError(f"--hdr {str(folder)!r} holds the frame {loose[0]!r} beside its sequence folders: "
                         "put every frame in a sequence's sub-folder")
    sources = []
    for sub in subfolders:
        check_name(sub.name, "sequence (HDR sub-folder)")
        nested = sorted(p.name for p in sub.iterdir() if p.is_dir() and not p.name.startswith("."))
        if nested:                  # (its frames were dropped without a word)
            raise InputError(f"sequence folder {str(sub)!r} holds the folder {nested[0]!r}: a sequence is one "
                             "folder of frames (sequences sit side by side in --hdr)")
        paths = list_frames(sub)
        if max_frames is not None:
            paths = paths[:max_frames]
        height, width = sequence_size(paths, f"sequence {sub.name!r}")   # every frame, before the plan
        read_gray(str(paths[0]), weights)                                  # (its channels: one frame decoded)
        sources.append(Source(sub.name, (len(paths), height, width), f"hdr:{sub.name} ({weights})",
                              frames=tuple(str(p) for p in paths), weights=weights,
                              digest=frames_digest(paths)))
    return sources


def scene_sources(names: Sequence[str], frames: int, height: int, width: int) -> list[Source]:
    """Built-in scenes (public seed 0, peak 1), each named after its scene."""
    from tespike.recon.scenes import check_scene_request
    from tespike.recon.settings import names as name_list

    names = name_list(names, "scene names")              # (one name given as text: its letters had been names)
    out = []
    for name in names:
        check_scene_request(name, frames, height, width, flags=True)
        out.append(Source(name, (frames, height, width), f"scene:{name} seed 0",
                          scene=(name, frames, height, width)))
    return out


# ---------------------------------------------------------------- tasks
def frames_peak(source: Source, start: int, stop: int) -> float:
    """Largest grayscale value of frames [start, stop) (checks their size)."""
    top = 0.0
    for path in source.frames[start:stop]:
        gray = read_gray(path, source.weights)
        if gray.shape != source.shape[1:]:
            raise InputError(f"frame {path!r} is {gray.shape[0]} x {gray.shape[1]}, but the first frame "
                             f"of sequence {source.name!r} is {source.shape[1]} x {source.shape[2]}; "
                             "all frames of a sequence must have the same size")
        top = max(top, float(gray.max()))
    return top


def write_hdr_light(url: str, source: Source, start: int, stop: int, top: float) -> float:
    """Write light[start:stop] = gray / top (float64 product, stored float32); return its maximum."""
    if not top > 0:
        raise InputError(f"HDR sequence {source.name!r}: every pixel is 0, so it cannot be "
                         "normalised by its maximum")
    scale = 1.0 / top
    tiny = float(np.finfo(np.float32).tiny)
    out = np.empty((stop - start,) + source.shape[1:], np.float32)
    for k, path in enumerate(source.frames[start:stop]):
        light = read_gray(path, source.weights).astype(np.float64) * scale
        darkest = float(np.min(light, where=light > 0, initial=np.inf))
        if darkest < tiny:            # float32 would round it to a subnormal or 0 (scene --folder refuses it)
            raise InputError(f"HDR frame {path!r}: its darkest lit value is {darkest:.3g} of the sequence's "
                             f"brightest, below float32's normal range (from {tiny:.3g}), in which the store "
                             "holds the light: it would lose precision or become zero")
        out[k] = light
    open_array(url, f"{source.name}/light", "r+")[start:stop] = out
    return float(out.max())


def write_scene_light(url: str, source: Source) -> float:
    """Make a built-in scene and write it whole (scenes are bounded by recon.scenes.MAX_VOXELS)."""
    from tespike.recon.scenes import make_scene
    name, frames, height, width = source.scene
    light = make_scene(name, frames, height, width, seed=0)
    open_array(url, f"{source.name}/light", "r+")[...] = light
    return float(light.max())


def simulate_tile(url: str, sequence: str, sensor: str, config_json: str, seed: int,
                  row: int, col: int, rows: slice, cols: slice, *after) -> int:
    """Simulate one tile of one stream over the whole sequence; return its pixel-readouts.

    ``after`` only orders the task after the light is written.
    """
    from tespike.golden.decode import check_words
    from tespike.golden.fastsim import SceneSimulator
    from tespike.golden.io import word_dtype

    config = SensorConfig.from_json(config_json)
    light = open_array(url, f"{sequence}/light")
    words = open_array(url, f"{sequence}/streams/{sensor}", "r+")
    K, H, W = light.shape
    shape = (rows.stop - rows.start, cols.stop - cols.start)
    sim = SceneSimulator(config, shape, rng=np.random.default_rng(tile_seed(seed, sequence, config, row, col)),
                         total_pixel_readouts=K * H * W)
    step = light.chunks[0]
    out = np.empty((step,) + shape, word_dtype(config))
    for start in range(0, K, step):
        stop = min(K, start + step)
        chunk = light[start:stop, rows, cols]
        for k in range(stop - start):
            out[k] = sim.readout(chunk[k].astype(np.float64))
        check_words(out[:stop - start], config)          # a store never holds an illegal word
        words[start:stop, rows, cols] = out[:stop - start]
    return K * shape[0] * shape[1]


def finish_array(url: str, path: str, *after, **attrs) -> bool:
    """Mark one array complete (after every task that writes it)."""
    mark_complete(url, path, **attrs)
    return True


def finish_light(url: str, path: str, peaks: list, top: float | None = None, source: Source | None = None) -> float:
    """Mark the light complete with its peak (and the source maximum it was divided by); HDR frames are
    hashed again first, so that light read from frames replaced during the run is never marked
    complete under the digest of the frames it was planned from (a resume then mixed two inputs)."""
    if source is not None and source.frames and frames_digest(source.frames) != source.digest:
        raise InputError(f"the frames of sequence {source.name!r} changed while this run read them "
                         f"({str(Path(source.frames[0]).parent)!r}): run the command again once they stay as they are")
    peak = max(peaks)
    mark_complete(url, path, peak=peak, **({} if top is None else {"source_max": top}))
    return peak


def finish_sequence(url: str, sequence: str, *after) -> str:
    """Last write of a sequence: copy the light's peak up, drop files a killed writer left
    (``*.partial``, local stores), and set ``complete: true``."""
    import zarr

    peak = zarr.open_array(url, path=f"{sequence}/light", mode="r").attrs["peak"]
    if "://" not in url:
        for stray in Path(url, sequence).rglob("*.partial"):
            stray.unlink(missing_ok=True)
    mark_complete(url, sequence, peak=peak)
    return sequence


# ---------------------------------------------------------------- graph
def sequence_graph(store: DatasetStore, source: Source):
    """The delayed task that completes one sequence (None when it is already complete) and the
    number of streams it simulates."""
    from dask import delayed

    done = store.prepare_sequence(source.name, source.shape, source.description, source.digest)
    if done["sequence"]:
        return None, 0
    url, name = store.url, source.name
    K, H, W = source.shape
    light_done = None
    if not done["light"]:
        step = store.chunk_frames
        if source.scene is not None:
            peaks = [delayed(write_scene_light, pure=False)(url, source, dask_key_name=f"light-{name}")]
            top = None
        else:
            chunks = [(s, min(K, s + step)) for s in range(0, K, step)]
            maxima = [delayed(frames_peak, pure=False)(source, s, e, dask_key_name=f"peak-{name}-{s}")
                      for s, e in chunks]
            top = delayed(max, pure=False)(maxima, dask_key_name=f"top-{name}")
            peaks = [delayed(write_hdr_light, pure=False)(url, source, s, e, top,
                                                          dask_key_name=f"light-{name}-{s}")
                     for s, e in chunks]
        light_done = delayed(finish_light, pure=False)(url, f"{name}/light", peaks, top, source,
                                                       dask_key_name=f"light-done-{name}")
    streams = []
    for sensor, config in store.configs.items():
        if done[sensor]:
            continue
        parts = [delayed(simulate_tile, pure=False)(url, name, sensor, config.to_json(), store.seed,
                                                    r, c, rows, cols, light_done,
                                                    dask_key_name=f"sim-{name}-{sensor}-{r}-{c}")
                 for r, c, rows, cols in tiles(H, W, store.tile)]
        streams.append(delayed(finish_array, pure=False)(url, f"{name}/streams/{sensor}", *parts,
                                                         dask_key_name=f"stream-done-{name}-{sensor}"))
    return delayed(finish_sequence, pure=False)(url, name, light_done, *streams,
                                                dask_key_name=f"sequence-done-{name}"), len(streams)


def build_dataset(url: str, sources: Sequence[Source], configs: dict[str, SensorConfig], seed: int, run, *,
               chunk_frames: int = CHUNK_FRAMES, tile: tuple[int, int] = TILE, report=None, notice=None,
               starting=None, progress=None) -> dict:
    """Write every source into the store at ``url`` (made or resumed) with every configuration.

    ``run`` is a :class:`tespike.cosim.dataset.cluster.Runner`; ``report(name)`` is
    called as each sequence completes, ``notice(text)`` for each sequence a resumed
    store held complete but with a damaged chunk (its CRC-32C fails), which is rebuilt;
    ``starting()`` once the store is made or resumed and every sequence checked, before any is
    simulated (so a refusal comes before the command says what it will do). ``progress``: None, or
    ``progress(total)`` -> a function that wraps the iterable of completed sequences and reports as
    it is walked (``tespike dataset`` passes a tqdm bar).
    Returns counts: ``done`` (sequences written now, rebuilt ones included),
    ``skipped`` (already complete), ``pixel_readouts`` (simulated now, summed over
    the streams), ``rebuilt`` (names of the damaged sequences rebuilt).
    """
    if type(seed) is not int or seed < 0:
        raise InputError(f"--seed {seed!r} must be an integer >= 0")
    if not callable(run):                                # (None had been a TypeError after the store was made)
        raise InputError(f"run: must run the build's tasks (a Runner), not {type(run).__name__}")
    if isinstance(sources, (str, bytes)) or not all(isinstance(s, Source) for s in sources):
        raise InputError("sources: must be a sequence of Source (hdr_sources, scene_sources)")
    if not isinstance(configs, dict):
        raise InputError(f"configs: must map sensor names to configurations, not {type(configs).__name__}")
    for name, config in configs.items():
        SensorConfig.required(config, f"sensor {name!r}")
    if type(chunk_frames) is not int or chunk_frames < 1:
        raise InputError(f"--chunk-frames {chunk_frames!r} must be an integer >= 1")
    names = [s.name for s in sources]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise InputError(f"sequence name {repeated[0]!r} is given twice (HDR sub-folders and "
                         "--scene names share one namespace)")
    if not sources:
        raise InputError("nothing to build: give --hdr DIR and/or --scene NAME")
    if not configs:
        raise InputError("no sensor configuration: give --config at least once")
    graphs, skipped, pixel_readouts, done, checked = [], 0, 0, 0, False
    try:
        store = DatasetStore.create_or_resume(url, seed=seed, configs=configs, tile=tile,
                                              chunk_frames=chunk_frames)
        for source in sources:
            graph, streams = sequence_graph(store, source)
            if graph is None:
                skipped += 1
            else:
                graphs.append(graph)
                pixel_readouts += int(np.prod(source.shape)) * streams
            damaged = store.rebuilt.get(source.name)
            if damaged and notice is not None:
                notice(f"sequence {source.name!r} was complete, but {damaged[0]}"
                       f"{f' (and {len(damaged) - 1} more)' if len(damaged) > 1 else ''}: rebuilding "
                       "what is damaged")
        checked = True
        if starting is not None:
            starting()
        for _, name in (iter if progress is None else progress(len(graphs)))(run(graphs)):
            done += 1
            if report is not None:
                report(name)
    except BaseException as exc:       # a bad frame, Ctrl-C, a lost cluster: say what a rerun resumes
        refused = isinstance(exc, InputError) and not checked   # (a store refused as it stands: no rerun resumes it)
        full = isinstance(exc, OSError) and exc.filename is None and exc.errno in NO_ROOM
        if full:                       # Zarr's writes (here or on a worker) name no file
            exc = InputError(f"cannot write dataset store {os.fspath(url)!r}: {exc.strerror}")
        if not refused:
            note_resumable(exc, url, done + skipped)
        if full:
            raise exc from None
        raise
    return {"done": done, "skipped": skipped, "pixel_readouts": pixel_readouts,
            "store": os.fspath(url), "rebuilt": sorted(store.rebuilt)}


@contextlib.contextmanager
def writing_local_store(url: str):
    """Hold the local store ``url`` for this run alone -> ``"new"`` where this run made its folder,
    ``"empty"`` where it is an empty folder (a store this run would make), else None (a store to
    resume, or a remote one, which is not held). The folder is made here (``mkdir``, atomic) and held
    with an exclusive ``flock`` until the ``with`` ends: a second ``tespike dataset`` writing the same
    store is refused in one line. Unheld, two runs with other seeds had both ended with exit 0 on a
    store whose chunks mixed their streams, or one run had removed the store the other was writing."""
    url = os.fspath(url)
    if "://" in url:
        yield None
        return
    made = None
    if not os.path.lexists(url):
        with contextlib.suppress(FileExistsError):      # (another run made it just now: held, or refused, below)
            os.mkdir(url)
            made = "new"
    if not os.path.isdir(url):                         # (the store's own checks refuse it)
        yield None
        return
    with folder_held(url, f"dataset store {url!r}") as still_named:
        if made is None and not os.listdir(url):
            made = "empty"
        yield made
        if not still_named():
            # removed during the run and made again by a write (Zarr makes a missing group's folders):
            # the store held a root without its dataset attributes, which every command refused, exit 0
            raise InputError(f"dataset store {url!r} was removed during the run; what was written after "
                             "is not a dataset store: remove it and run again")


#: The end of the note a failed build's error carries when its store keeps complete sequences.
RESUMES = "the same command resumes it)"


def note_resumable(exc: BaseException, url: str, complete: int) -> None:
    """Say on ``exc``, once, that store ``url`` keeps ``complete`` (> 0) complete sequences a rerun resumes."""
    if complete and not any(note.endswith(RESUMES) for note in getattr(exc, "__notes__", ())):
        exc.add_note(f"(store {os.fspath(url)!r} keeps {complete} complete sequence(s); {RESUMES}")


def discard_unfinished_store(url: str, made: str | None) -> int:
    """After a failed or interrupted build (its workers stopped): remove the store this run made
    (``made`` from :func:`writing_local_store`; an "empty" folder given is emptied, not removed) if it
    holds no complete sequence, so that a run that made nothing leaves nothing -> the complete
    sequences of a store kept (0 where it was removed or emptied, or not this run's)."""
    import shutil
    if made is None or not os.path.isdir(url):
        return 0
    try:
        complete = DatasetStore.open(url).sequences(complete=True)
        if complete:
            return len(complete)                     # resumable work: kept, and the error says so
    except (InputError, OSError, ValueError, KeyError):
        pass                                         # not even a readable store yet
    if made == "new":
        shutil.rmtree(url, ignore_errors=True)
        return 0
    for entry in os.scandir(url):
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                os.unlink(entry.path)
    return 0
