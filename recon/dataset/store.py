"""The dataset store: one Zarr (v3) store of light sequences and their sensor streams.

Layout (every name below is a Zarr group or array; ``STORE`` is a folder, or
any URL Zarr opens, shared by every machine that writes or reads it)::

    STORE/                        attrs: format, version, seed, configs {name: SPEC dict},
                                         tile [rows, cols], chunk_frames
      <sequence>/                 attrs: source, frames, height, width, peak, scale, complete
        light                     float32 (K, H, W): the ground-truth light, as the scene
                                  (1.0 = design light, peak 1 per sequence, paper A.2.2)
        streams/<config>          uint8/uint16 (K, H, W): readout words (golden.io.word_dtype)
                                  attrs: config (JSON), seed, seed_key, complete

Arrays are chunked as (``chunk_frames``, ``tile``) and compressed (Blosc zstd,
bit shuffle), each compressed chunk followed by its CRC-32C (stores made before have none and
read as they did). The simulation tile (default 256 x 256) is part of the format:
each tile of each stream is simulated with its own random stream, seeded by
:func:`tile_seed` from the root seed, a SHA-256 of the sequence name and the
configuration JSON, and the tile's position, so a store is bit-identical
whatever the number of workers or the order in which tasks finish.

Atomicity: a sequence is visible to readers (:meth:`DatasetStore.sequences`)
only once its group carries ``complete: true``, an attribute written last,
after every array of the sequence is written and itself marked complete (Zarr
writes a ``zarr.json`` by temporary file and rename, so the flag appears whole
or not at all). Incomplete groups are ignored by readers and finished (or
redone) by the next `tespike dataset` run; chunk writes are idempotent (the same bytes
every time), so a task that is retried after its worker died rewrites exactly
what it wrote before.

This module needs numpy, zarr and dask only (no simulator, no torch), so the
evaluation and the training read the store through it.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import re
import shutil
import warnings
from pathlib import Path

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count, one_line
from tespike.golden.io import check_frame_shape, word_dtype
from tespike.golden.paths import path_text

FORMAT = "tespike-dataset"
VERSION = 1
#: Simulation tile (rows, cols): the unit of parallel work and of random streams.
TILE = (256, 256)
#: Readouts per chunk along time (memory of one task: chunk_frames x tile).
CHUNK_FRAMES = 16
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")


#: Node names Zarr's stores use for their own files (a sequence of that name would collide).
RESERVED_NAMES = ("zarr.json",)


def check_name(name: str, what: str) -> str:
    """Sequence and sensor names become Zarr node names: letters, digits, ``_ . + -``, and not the
    name of Zarr's own metadata file (a folder ``zarr.json`` would collide with the group's)."""
    if not isinstance(name, str) or not _NAME.match(name) or name.startswith("__"):
        raise InputError(f"{what} name {name!r} must start with a letter or digit and hold only "
                         "letters, digits and _ . + -")
    if name.lower() in RESERVED_NAMES:
        raise InputError(f"{what} name {name!r} is reserved: it is the name of Zarr's metadata files "
                         "(rename it)")
    return name


def seed_key(sequence: str, config: SensorConfig) -> list[int]:
    """Eight 32-bit words of SHA-256(sequence name, NUL, configuration JSON): stable across
    runs, machines and Python versions (unlike ``hash()``)."""
    digest = hashlib.sha256(f"{sequence}\0{config.to_json()}".encode()).digest()
    return [int.from_bytes(digest[i:i + 4], "little") for i in range(0, 32, 4)]


def tile_seed(seed: int, sequence: str, config: SensorConfig, row: int, col: int) -> np.random.SeedSequence:
    """The random stream of tile (row, col) (tile indices, not pixels) of one stream."""
    config = SensorConfig.required(config, "tile_seed")
    for name, value in (("seed", seed), ("row", row), ("col", col)):
        if not is_count(value):                          # (2.5 had been taken as 2, -1 numpy's error)
            raise InputError(f"tile_seed {name} {value!r}: must be an integer >= 0")
    return np.random.SeedSequence([int(seed), *seed_key(sequence, config), int(row), int(col)])


def tiles(height: int, width: int, tile: tuple[int, int] = TILE) -> list[tuple[int, int, slice, slice]]:
    """(row, col, rows, cols) of every tile of an H x W frame, row-major; edge tiles are smaller."""
    height, width = check_frame_shape((height, width), "frame (height, width)")
    th, tw = check_frame_shape(tile, "tile (rows, cols)")      # (0 had been a ZeroDivisionError)
    return [(r, c, slice(r * th, min(height, (r + 1) * th)), slice(c * tw, min(width, (c + 1) * tw)))
            for r in range(-(-height // th)) for c in range(-(-width // tw))]


def _compressors():
    """Blosc zstd with bit shuffle, then a CRC-32C of each compressed chunk: Blosc checks nothing,
    so a flipped byte of a chunk decompressed into other values (and scores) without one."""
    from zarr.codecs import BloscCodec, Crc32cCodec
    return (BloscCodec(cname="zstd", clevel=3, shuffle="bitshuffle"), Crc32cCodec())


def _check_zarr_format(group, url: str, what: str) -> None:
    """Refuse a store of another Zarr format than this build writes (3): writing into a version-2
    store failed mid-way with a traceback after replacing a sequence's arrays with version-2 groups."""
    version = getattr(getattr(group, "metadata", None), "zarr_format", 3)
    if version != 3:
        raise InputError(f"{what} {url!r} is a Zarr format {version} store; tespike dataset stores are "
                         "Zarr format 3 (it is left untouched)")


def _zarr_open_group(url: str, mode: str, missing_ok: bool = False):
    """The store's root group, or one line saying why it cannot be read (``missing_ok``: None
    where there is no store yet)."""
    import zarr
    try:
        return zarr.open_group(url, mode=mode)
    except FileNotFoundError:
        if missing_ok:
            return None
        import os
        local = "://" not in url
        there = local and os.path.isdir(url)                  # a local folder without a store's zarr.json
        dangling = local and os.path.islink(url) and not os.path.exists(url)   # (a loop, or gone)
        a_file = local and os.path.lexists(url) and not there and not dangling
        if there and os.path.isfile(os.path.join(url, "zarr.json")):   # (Zarr read it as no group at all)
            raise InputError(f"{url!r} is not a readable Zarr store (its {os.path.join(url, 'zarr.json')!r}): "
                             f"its node_type is {_node_type(Path(url, 'zarr.json'))}, not 'group'") from None
        raise InputError(f"dataset store {url!r} " + ("is a folder but not a dataset store (it holds no zarr.json)"
                                                     if there else "is a file, not a dataset store (a folder)"
                                                     if a_file else "is a link to nothing (a loop, or a "
                                                     "target that is gone)" if dangling else "does not exist")
                         ) from None
    except (ValueError, TypeError, KeyError) as exc:      # not a Zarr v3 group, bad JSON
        where = f" (its {str(Path(url, 'zarr.json'))!r})" if "://" not in url else ""
        raise InputError(f"{url!r} is not a readable Zarr store{where}: {one_line(exc, 200)}") from None
    except RecursionError:                                # JSON nested too deeply for the parser
        raise InputError(f"{url!r} is not a readable Zarr store: its zarr.json is nested too deeply "
                         "to read as JSON") from None


class DatasetStore:
    """A dataset store (layout in the module docstring): create, check, read lazily."""

    def __init__(self, url: str, group, attrs: dict):
        self.url = str(url)
        self.group = group
        what = f"dataset store {self.url!r}"
        self.seed = _attribute(attrs, "seed", what, lambda v: type(v) is int and v >= 0, "an integer >= 0")
        configs = _attribute(attrs, "configs", what, lambda v: isinstance(v, dict) and v, "an object of configurations")
        try:
            self.configs = {check_name(name, "sensor configuration"): SensorConfig.from_dict(d)
                            for name, d in configs.items()}
        except (InputError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"{what}: its configs are not valid ({one_line(exc, 160)})") from None
        self.tile = tuple(_attribute(attrs, "tile", what, lambda v: isinstance(v, list) and len(v) == 2 and all(
            type(n) is int and n >= 1 for n in v), "two integers >= 1"))
        self.chunk_frames = _attribute(attrs, "chunk_frames", what, lambda v: type(v) is int and v >= 1,
                                       "an integer >= 1")
        #: sequence -> what :meth:`prepare_sequence` found damaged (chunk files), whose arrays it made anew
        self.rebuilt: dict[str, list[str]] = {}

    # -- opening --------------------------------------------------------------
    @classmethod
    def open(cls, url: str, mode: str = "r") -> "DatasetStore":
        """Open an existing store (``mode`` "r" or "r+"); refuse anything else, before Zarr sees it
        (Zarr's "w" clears the folder it is given: ``open('/tmp', 'w')`` had emptied /tmp)."""
        url = path_text(url, "dataset store")               # (a number had been "does not exist")
        if mode not in ("r", "r+"):
            raise InputError(f"dataset store mode {mode!r}: must be 'r' or 'r+' (an existing store; "
                             "DatasetStore.create_or_resume makes one)")
        group = _zarr_open_group(url, mode)
        _check_zarr_format(group, url, "dataset store")
        attrs = group.attrs.asdict()
        if attrs.get("format") != FORMAT:
            raise InputError(f"{url!r} is a Zarr store but not a tespike dataset store")
        if attrs.get("version") != VERSION:
            raise InputError(f"dataset store {url!r} has version {attrs.get('version')!r}; "
                             f"this tespike reads version {VERSION}")
        return cls(url, group, attrs)

    @classmethod
    def create_or_resume(cls, url: str, *, seed: int, configs: dict[str, SensorConfig],
                         tile: tuple[int, int] = TILE, chunk_frames: int = CHUNK_FRAMES) -> "DatasetStore":
        """A new store, or an existing one made with the same seed, configurations,
        tile and chunking (anything else is refused: the streams would not match)."""
        import zarr

        url = path_text(url, "dataset store")
        if not is_count(seed):                              # (int() had truncated 2.5 silently)
            raise InputError(f"dataset store seed {seed!r}: must be an integer >= 0")
        if not isinstance(configs, dict) or not configs:
            raise InputError("dataset store configs: must map one or more sensor names to configurations")
        for name, config in configs.items():
            check_name(name, "sensor configuration")
            SensorConfig.required(config, f"sensor {name!r}")
        tile = check_frame_shape(tile, "dataset store tile (rows, cols)")   # (2.5 had been stored as 2)
        if not is_count(chunk_frames, 1):
            raise InputError(f"dataset store chunk_frames {chunk_frames!r}: must be an integer >= 1")
        attrs = {"format": FORMAT, "version": VERSION, "seed": int(seed),
                 "configs": {name: c.to_dict() for name, c in configs.items()},
                 "tile": [int(t) for t in tile], "chunk_frames": int(chunk_frames)}
        group = _zarr_open_group(url, "r+", missing_ok=True)
        if group is None:
            import os
            if "://" not in url and os.path.exists(url) and (not os.path.isdir(url) or os.listdir(url)):
                raise InputError(f"--out {url!r} exists and is not a dataset store; "
                                 "it is left untouched")
            group = zarr.open_group(url, mode="w-")
            group.attrs.update(attrs)
            return cls(url, group, attrs)
        _check_zarr_format(group, url, "--out")        # (before anything is written into it)
        old = group.attrs.asdict()
        if old.get("format") != FORMAT:
            raise InputError(f"--out {url!r} is a Zarr store but not a tespike dataset store")
        for key in ("version", "seed", "configs", "tile", "chunk_frames"):
            if json.dumps(old.get(key), sort_keys=True) != json.dumps(attrs[key], sort_keys=True):
                was, now = old.get(key), attrs[key]
                if key == "configs" and isinstance(was, dict):      # name the sensors, not two long dicts
                    was, now = sorted(was), sorted(now)
                    if was == now:
                        raise InputError(f"dataset store {url!r} was made with other settings of the sensor "
                                         f"configurations {', '.join(now)}: resume with the same ones or use "
                                         "a new --out")
                raise InputError(f"dataset store {url!r} was made with {key} = {was!r}, "
                                 f"not {now!r}: resume with the same settings or use a new --out")
        return cls(url, group, old)

    # -- layout ---------------------------------------------------------------
    def chunks(self, height: int, width: int) -> tuple[int, int, int]:
        return (self.chunk_frames, min(self.tile[0], height), min(self.tile[1], width))

    def prepare_sequence(self, name: str, shape: tuple[int, int, int], source: str,
                         digest: str = "") -> dict[str, bool]:
        """Make (or keep) the group and arrays of one sequence; return which parts are
        already complete: ``{"sequence": ..., "light": ..., <config>: ...}``.

        A complete sequence must match ``shape``, ``source`` and, for frames read from files,
        their content ``digest``; an unfinished one that does not is made anew, and so are
        unfinished arrays (their chunks are rewritten by the next build anyway).
        """
        check_name(name, "sequence")
        if not (isinstance(shape, (tuple, list)) and len(shape) == 3 and all(is_count(n, 1) for n in shape)):
            raise InputError(f"sequence {name!r} shape {shape!r}: must be (K, H, W), integers >= 1")
        for what, text in (("source", source), ("digest", digest)):
            if not isinstance(text, str):                # (5 or None had been stored)
                raise InputError(f"sequence {name!r} {what} {text!r}: must be text")
        K, H, W = (int(n) for n in shape)
        info = {"source": source, "frames": K, "height": H, "width": W, **({"digest": digest} if digest else {})}
        self._rebuild_if_unreadable(name)
        if name in self.group:
            group = self.group[name]
            old = group.attrs.asdict()
            mismatch = [k for k, v in info.items() if old.get(k) != v
                        and not (k == "digest" and "digest" not in old)]   # (stores made before digests)
            altered = [k for k in mismatch if type(old.get(k)) is not type(info[k])]   # (None: missing)
            if mismatch and old.get("complete") and altered:    # damage, not another sequence: made again
                self.rebuilt.setdefault(name, []).append(f"its attribute {altered[0]} is {old.get(altered[0])!r}")
                del self.group[name]
            elif mismatch:
                if old.get("complete") and mismatch == ["digest"]:
                    raise InputError(f"sequence {name!r} in {self.url!r} was made from frames whose files have "
                                     "changed since (the same names, other bytes): use a new --out, or remove "
                                     "the sequence from the store to build it again from these frames")
                if old.get("complete"):
                    raise InputError(f"sequence {name!r} in {self.url!r} was made with "
                                     f"{mismatch[0]} = {old.get(mismatch[0])!r}, not {info[mismatch[0]]!r}")
                del self.group[name]                        # an unfinished different sequence
            elif old.get("complete") and not _is_peak(old.get("peak")):   # (check_sequence refuses it)
                self.rebuilt.setdefault(name, []).append(f"its peak attribute is {old.get('peak')!r}")
                del self.group[name]                        # the light's build writes it: made again
        if name not in self.group:
            group = self.group.create_group(name)
            group.attrs.update({**info, "complete": False})
        group = self.group[name]
        done = {"sequence": bool(group.attrs.get("complete", False))}
        chunks = self.chunks(H, W)
        arrays = {"light": np.dtype(np.float32),
                  **{f"streams/{c}": word_dtype(config) for c, config in self.configs.items()}}
        for path, dtype in arrays.items():
            key = path.split("/")[-1]
            with reading(self.url, f"{name}/{path}"):
                complete = path in group and bool(group[path].attrs.get("complete", False))
            damaged = [f"chunk {chunk!r} fails its CRC-32C check"
                       for chunk in (damaged_chunks(self.url, f"{name}/{path}") if complete else [])]
            if complete and not damaged:      # what check_sequence refuses of an array, here rebuilt
                with reading(self.url, f"{name}/{path}"):
                    problem = self._array_problem(group[path], path, (K, H, W))
                damaged = [] if problem is None else [problem]
            if complete and not damaged:
                with reading(self.url, f"{name}/{path}"):
                    recorded = group[path].attrs.get("chunk_files")
                missing = missing_chunks(self.url, f"{name}/{path}", recorded)
                if missing:                 # (a deleted chunk file would read as zeros)
                    damaged = [f"{str(Path(self.url, name, *path.split('/'), 'c'))!r} has {recorded - missing[0]} "
                               f"of its {recorded} chunk files missing"]
            if not complete and done["sequence"]:     # a complete sequence whose array was removed or reset
                damaged = [f"its array {path} is missing or unfinished"]
            if damaged:              # kept work is verified: a damaged chunk's array is made again
                self.rebuilt.setdefault(name, []).extend(damaged)
                complete = False
                if done["sequence"]:
                    group.attrs.update(complete=False)          # readers skip it until rebuilt
                    done["sequence"] = False
            if not complete:
                array = group.create_array(path, shape=(K, H, W), chunks=chunks, dtype=dtype,
                                           compressors=_compressors(), fill_value=0, overwrite=True)
                if key in self.configs:
                    config = self.configs[key]
                    array.attrs.update({"config": config.to_json(), "seed": self.seed,
                                        "seed_key": seed_key(name, config), "tile": list(self.tile),
                                        "complete": False})
                else:
                    array.attrs.update({"complete": False})
            done[key] = complete
        return done

    # -- reading --------------------------------------------------------------
    def _rebuild_if_unreadable(self, name: str) -> None:
        """A sequence whose group metadata Zarr cannot read (its ``zarr.json`` cut short, not JSON, or
        a key of it renamed by a flipped byte) is removed, to be made anew like a damaged chunk's
        array; where the store is not a local folder, one line names the cause."""
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if name in self.group or Path(self.url, name, "zarr.json").is_file():   # (not "in" if unreadable)
                    import zarr
                    node = self.group[name]
                    node.attrs.asdict()
                    if not isinstance(node, zarr.Group):      # (its node_type altered: creating a group failed)
                        raise ValueError(f"{name!r} is an array, not a sequence's group")
            return
        except _DAMAGE as exc:
            if _starved(exc):
                raise                     # (a sound sequence is not removed for want of a thread)
            where = damaged_file(self.url, name)
            if where is None:
                raise InputError(f"sequence {name!r} of dataset store {self.url!r} cannot be read "
                                 f"({one_line(exc, 160)})") from None
        self.rebuilt.setdefault(name, []).append(f"{where!r} is damaged")
        shutil.rmtree(Path(self.url, name))

    def sequences(self, *, complete: bool = True) -> list[str]:
        """Sequence names, sorted; only complete ones unless ``complete=False``. A local store's
        folder holding a sequence's arrays but no ``zarr.json`` is refused (Zarr skipped it with a
        warning, and the table's means left it out)."""
        import warnings
        if Path(self.url).is_dir():
            for folder in sorted(Path(self.url).iterdir()):
                sequence_like = folder.is_dir() and ((folder / "light").exists() or (folder / "streams").exists())
                if sequence_like and not (folder / "zarr.json").exists():
                    raise InputError(f"dataset store file {str(folder / 'zarr.json')!r} is missing (the sequence "
                                     f"{folder.name!r} is damaged); remove its folder and run tespike dataset "
                                     "again to rebuild it")
                kind = _node_type(folder / "zarr.json") if sequence_like and (folder / "zarr.json").is_file() else None
                if kind not in (None, "'group'"):
                    raise InputError(f"dataset store file {str(folder / 'zarr.json')!r} is damaged (its node_type is "
                                     f"{kind}); remove its sequence's folder and run tespike dataset again to "
                                     "rebuild it")
        try:
            with warnings.catch_warnings():           # (Zarr warns of each stray file or folder)
                warnings.simplefilter("ignore")
                names = sorted(self.group.group_keys())
        except _DAMAGE:                   # listing reads every sequence's zarr.json: name the bad one
            folders = sorted(p.name for p in Path(self.url).iterdir() if p.is_dir()) if Path(self.url).is_dir() else []
            for child in folders:
                with reading(self.url, child):
                    self.group[child]
            raise
        done = []
        for name in names:
            with reading(self.url, name):
                if not complete or self.group[name].attrs.get("complete", False):
                    done.append(name)
        return done

    def check_sequence(self, name: str) -> dict:
        """The attributes of complete sequence ``name`` once its metadata is consistent: sizes and
        peak of the kind a build writes, every array of the sequence's (frames, height, width)
        shape, each stream made for the root's configuration of its name, and (a local store)
        every chunk file a build wrote still there: Zarr reads a missing chunk as zeros. One line
        naming the sequence otherwise (its folder must be rebuilt)."""
        info = self.info(name)
        what = f"sequence {name!r} of dataset store {self.url!r}"
        for key in ("frames", "height", "width"):
            _attribute(info, key, what, lambda v: type(v) is int and v >= 1, "an integer >= 1")
        _attribute(info, "peak", what, _is_peak, "a number in (0, 1e30)")
        shape = (info["frames"], info["height"], info["width"])
        for part in ("light", *(f"streams/{c}" for c in self.configs)):
            with reading(self.url, f"{name}/{part}"):
                present = part in self.group[name]
            if not present:
                raise InputError(f"{what}: its array {part} is missing; remove its folder and run tespike "
                                 "dataset again")
            array = self.array(name, part)
            if array.attrs.get("complete") is not True:
                raise InputError(f"{what}: its array {part} was never finished (not marked complete); remove "
                                 "its folder and run tespike dataset again")
            problem = self._array_problem(array, part, shape)
            if problem is not None:
                raise InputError(f"{what}: {problem}; remove its folder and run tespike dataset again")
            missing = missing_chunks(self.url, f"{name}/{part}", array.attrs.get("chunk_files"))
            if missing:
                raise InputError(f"{what}: {part} holds {missing[0]} of the {missing[1]} chunk files its build "
                                 "wrote (Zarr would read the others as zeros); remove its folder and run "
                                 "tespike dataset again")
        return info

    def _array_problem(self, array, part: str, shape: tuple[int, int, int]) -> str | None:
        """What makes a finished array ``part`` of a sequence of ``shape`` unusable (another shape, a
        stream made for another configuration than the store's of its name), or None: read by
        :meth:`check_sequence` (refused) and :meth:`prepare_sequence` (rebuilt)."""
        if tuple(array.shape) != shape:
            return f"{part} has shape {tuple(array.shape)}, the sequence {shape}"
        key = part.split("/")[-1]
        if key in self.configs and array.attrs.get("config") != self.configs[key].to_json():
            return f"stream {key!r} was made for another configuration than the store's {key!r}"
        return None

    def info(self, sequence: str) -> dict:
        """Attributes of one sequence (source, frames, height, width, peak, scale, complete)."""
        if sequence not in self.group:
            raise InputError(f"dataset store {self.url!r} has no sequence {sequence!r}")
        with reading(self.url, sequence):
            return self.group[sequence].attrs.asdict()

    def light(self, sequence: str):
        """The ground-truth light of one sequence as a lazy dask array (K, H, W) float32."""
        import dask.array as da
        with reading(self.url, f"{sequence}/light"):
            return da.from_zarr(self.group[f"{sequence}/light"])

    def light_peak(self, sequence: str) -> float:
        """The largest value of a sequence's stored light, read a few frames at a time (the peak its
        attributes record must be it: it normalises every score)."""
        with reading(self.url, f"{sequence}/light"):
            light = self.group[f"{sequence}/light"]
            step = max(1, (1 << 22) // max(1, light.shape[1] * light.shape[2]))
            return max((float(np.max(light[k:k + step])) for k in range(0, light.shape[0], step)), default=0.0)

    def words(self, sequence: str, config: str):
        """The readout words of one sequence and sensor as a lazy dask array (K, H, W)."""
        import dask.array as da
        if config not in self.configs:
            raise InputError(f"dataset store {self.url!r} has no sensor {config!r} "
                             f"(it has {', '.join(self.configs)})")
        with reading(self.url, f"{sequence}/streams/{config}"):
            return da.from_zarr(self.group[f"{sequence}/streams/{config}"])

    def array(self, sequence: str, part: str):
        """The Zarr array ``light`` or ``streams/<config>`` of one sequence (for tasks)."""
        with reading(self.url, f"{sequence}/{part}"):
            return self.group[f"{sequence}/{part}"]


def _is_peak(value) -> bool:
    """A sequence's ``peak`` attribute as a build writes it: a number in (0, 1e30)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and 0 < value < 1e30


def _attribute(attrs: dict, key: str, what: str, ok, rule: str):
    """``attrs[key]`` where ``ok`` accepts it, else one line: the store's metadata was altered."""
    value = attrs.get(key)
    if key not in attrs or not ok(value):
        shown = "missing" if key not in attrs else f"{one_line(repr(value), 60)}"
        raise InputError(f"{what}: attribute {key} is {shown}, not {rule} (its zarr.json was altered; "
                         "rebuild it with tespike dataset)")
    return value


def open_array(url: str, path: str, mode: str = "r"):
    """One Zarr array of a store, opened in a task (workers open by URL, not by object); ``mode`` "r"
    or "r+" (Zarr's "w" would clear the array, as :meth:`DatasetStore.open` refuses it)."""
    import zarr
    if mode not in ("r", "r+"):
        raise InputError(f"dataset store array mode {mode!r}: must be 'r' or 'r+'")
    with reading(url, path):
        return zarr.open_array(str(url), path=path, mode=mode)


#: What a damaged store file raises while Zarr reads it: truncated JSON (ValueError), a chunk
#: that does not decompress (RuntimeError "error during blosc decompression"), odd metadata.
_DAMAGE = (ValueError, RuntimeError, KeyError, TypeError, EOFError)


@contextlib.contextmanager
def reading(url: str, path: str = ""):
    """Read node ``path`` of a store; a damaged file of it (a truncated ``zarr.json`` or chunk)
    becomes one :class:`InputError` naming that file and the cause, not Zarr's traceback."""
    try:
        yield
    except InputError:
        raise
    except (FileNotFoundError, *_DAMAGE) as exc:   # (FileNotFoundError: Zarr's "No array found ... at path")
        if _starved(exc):
            raise                                  # the command's line says what ran out, not the file
        where = None if isinstance(exc, FileNotFoundError) else damaged_file(str(url), path)
        if where is None:                          # no damaged file: maybe a node gone mid-run
            gone = _gone(str(url), path)
            if gone is None:
                raise
            refusal = InputError(gone)
        else:
            cause = ("its CRC-32C does not match its bytes" if "checksum do not match" in str(exc)   # (Zarr shows
                     else one_line(exc, 160))                                                      # both as bytes)
            refusal = InputError(f"dataset store file {where!r} is damaged ({cause}); remove its sequence's "
                                 "folder and run tespike dataset again to rebuild it")
    else:
        return
    _raise_unchained(refusal)


def _raise_unchained(error: BaseException):
    """Raise ``error`` with no exception chained to it. A Dask worker sends an exception back pickled
    with its context, and Zarr's errors do not unpickle: a refusal raised while one was handled (even
    ``from None``, which keeps the context) came back as a bare ``Exception(repr)``, a traceback."""
    try:
        raise error
    finally:
        error.__context__ = error.__cause__ = None


def _starved(exc: BaseException) -> bool:
    """Whether ``exc``, met while Zarr reads, is the process running out (a thread that cannot start:
    Zarr reads through a thread pool; an allocation that failed in a codec), not a damaged file:
    the file read again would read the same way, and a line calling it damaged sends the user to
    rebuild a sound store."""
    from tespike.entry import NO_ROOM_WORDS
    return isinstance(exc, RuntimeError) and any(word in str(exc) for word in NO_ROOM_WORDS)


def _gone(url: str, path: str) -> str | None:
    """Why node ``path`` of a local store cannot be found where a run opened it before: the store,
    or that part of it, was removed or moved during the run (the line says so); None elsewhere."""
    if "://" in url:
        return None
    if not Path(url).is_dir():
        return f"dataset store {url!r} is gone: it was removed or moved while the run read it"
    node = Path(url, *[part for part in path.split("/") if part])
    if path and not (node / "zarr.json").is_file():
        return (f"dataset store {url!r}: {path!r} is gone (removed while the run read it, or never "
                "built); run tespike dataset again to rebuild it")
    return None


def damaged_file(url: str, path: str = "") -> str | None:
    """The first file of a local store that cannot be read along ``path``: a ``zarr.json``
    (the root's, then each level's) that is not JSON, or a chunk of the array at ``path``
    that does not decode; None if every one reads (or the store is not a local folder)."""
    root = Path(url)
    if not root.is_dir():
        return None
    import zarr
    parts = [part for part in path.split("/") if part]
    for depth in range(len(parts) + 1):
        meta = root.joinpath(*parts[:depth], "zarr.json")
        try:
            document = json.loads(meta.read_bytes())
        except FileNotFoundError:
            continue
        except (OSError, ValueError, RecursionError):     # (nested too deeply for the parser)
            return str(meta)
        kind = document.get("node_type") if isinstance(document, dict) else None
        if kind not in ("group", "array") or (kind == "array" and depth < len(parts)):
            return str(meta)                              # (Zarr takes it as no node at all: not found)
        try:                                              # JSON, but not metadata Zarr reads (a key renamed)
            zarr.open(str(root), path="/".join(parts[:depth]), mode="r")
        except FileNotFoundError:
            continue
        except _DAMAGE as exc:
            if _starved(exc):
                raise
            return str(meta)
    try:
        import itertools
        array = zarr.open_array(str(root), path=path, mode="r")
        for index in itertools.product(*(range(n) for n in array.cdata_shape)):
            try:
                array.blocks[index]
            except _DAMAGE as exc:
                if _starved(exc):
                    raise
                return str(root.joinpath(*parts, array.metadata.encode_chunk_key(index)))
    except _DAMAGE as exc:
        if _starved(exc):
            raise
        return None
    return None


def _node_type(meta: Path) -> str:
    """The ``node_type`` of a ``zarr.json``, shown (``'array'``), or why there is none to show."""
    try:
        document = json.loads(meta.read_bytes())
    except (OSError, ValueError, RecursionError):
        return "unreadable (not JSON)"
    if not isinstance(document, dict) or "node_type" not in document:
        return "missing"
    return one_line(repr(document["node_type"]), 40)


def damaged_chunks(url: str, path: str) -> list[str]:
    """Chunk files of the array at ``path`` of a local store whose CRC-32C does not match their
    bytes (a truncated or altered chunk), without decompressing any: a resumed build keeps
    complete arrays, so it checks them first (about the cost of reading the files once).
    Empty for an array stored without CRCs (older stores) and for a store that is not a folder."""
    import google_crc32c
    folder = Path(url, *path.split("/"))
    if not folder.is_dir():
        return []
    with reading(url, path):
        meta = json.loads((folder / "zarr.json").read_bytes())
    if not any(isinstance(codec, dict) and codec.get("name") == "crc32c" for codec in meta.get("codecs", ())):
        return []
    bad = []
    for chunk in _chunk_files(folder):
        data = chunk.read_bytes()
        if len(data) < 4 or google_crc32c.value(data[:-4]) != int.from_bytes(data[-4:], "little"):
            bad.append(str(chunk))
    return bad


def _chunk_files(array_folder: Path) -> list[Path]:
    """The chunk files of a local array folder (under ``c/``, sorted; a write's ``.partial`` aside)."""
    chunks = array_folder / "c"
    return [chunk for chunk in sorted(chunks.rglob("*")) if chunk.is_file() and not chunk.name.endswith(".partial")] \
        if chunks.is_dir() else []


def chunk_file_count(url: str, path: str) -> int | None:
    """Chunk files of the array at ``path`` of a local store (None for a store that is not a
    folder). Zarr writes no chunk that holds only its fill value, so the count a build leaves is
    recorded (``chunk_files``) rather than derived from the shape."""
    if not Path(url).is_dir():
        return None
    return len(_chunk_files(Path(url, *path.split("/"))))


def missing_chunks(url: str, path: str, recorded) -> tuple[int, int] | None:
    """(present, recorded) where the array at ``path`` holds fewer chunk files than its build
    recorded; None where it holds them all, or nothing was recorded (older stores, remote ones)."""
    if type(recorded) is not int:
        return None
    present = chunk_file_count(url, path)
    return None if present is None or present >= recorded else (present, recorded)


def mark_complete(url: str, path: str, **attrs) -> None:
    """Write ``complete: true`` (and ``attrs``) on a group or array: the last write of a part. An
    array of a local store also records how many chunk files it holds (:func:`missing_chunks`)."""
    import zarr
    with reading(url, path):                        # (a node gone or damaged: one line naming it)
        node = zarr.open(str(url), path=path, mode="r+")
    count = chunk_file_count(url, path) if isinstance(node, zarr.Array) else None
    node.attrs.update({**attrs, **({} if count is None else {"chunk_files": count}), "complete": True})


def compare_stores(a: str, b: str) -> list[str]:
    """Differences between two stores (attributes, sequence names, every array bit for bit);
    an empty list when they are identical. For tests and for checking a rerun."""
    left, right = _zarr_open_group(str(a), "r"), _zarr_open_group(str(b), "r")   # (one line where either is none)
    out: list[str] = []

    def walk(x, y, where: str) -> None:
        if x.attrs.asdict() != y.attrs.asdict():
            out.append(f"{where or '/'}: attributes differ")
        xa, ya = sorted(x.array_keys()), sorted(y.array_keys())
        xg, yg = sorted(x.group_keys()), sorted(y.group_keys())
        if xa != ya or xg != yg:
            out.append(f"{where or '/'}: members differ ({xa + xg} vs {ya + yg})")
        for key in set(xa) & set(ya):
            p, q = x[key], y[key]
            if p.dtype != q.dtype or p.shape != q.shape:
                out.append(f"{where}/{key}: {p.dtype} {p.shape} vs {q.dtype} {q.shape}")
            elif p.attrs.asdict() != q.attrs.asdict():
                out.append(f"{where}/{key}: attributes differ")
            else:
                step = max(1, p.chunks[0])              # chunk by chunk over time: bounded memory
                if any(not np.array_equal(p[t:t + step], q[t:t + step]) for t in range(0, p.shape[0], step)):
                    out.append(f"{where}/{key}: values differ")
        for key in set(xg) & set(yg):
            walk(x[key], y[key], f"{where}/{key}")

    walk(left, right, "")
    return out
