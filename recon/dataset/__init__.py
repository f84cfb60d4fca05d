"""Datasets on disk: the Zarr dataset store of light sequences and sensor streams."""

from .store import CHUNK_FRAMES, TILE, DatasetStore, compare_stores, tile_seed, tiles

__all__ = ["DatasetStore", "compare_stores", "tile_seed", "tiles", "TILE", "CHUNK_FRAMES"]
