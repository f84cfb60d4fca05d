"""Every shipped weights file reconstructs a small stream as it did when its reference was written.

The reference (``tests/data/shipped_weights.npz``: the streams and, per file,
its images) pins what the shipped methods compute, so a refactoring of the
learned wing (module names, the shared alignment, the weights loader) that
changed a reconstruction fails here. Written once from the code before such a
change (bit-identical there); compared with a float tolerance, since another
CPU may round a convolution differently. Shipping new weights means writing
the reference again, on purpose: ``python3 tests/test_recon_shipped_weights.py --write``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

REFERENCE = Path(__file__).resolve().parent / "data" / "shipped_weights.npz"
#: The stream of each preset: (readouts, height, width), the height and width no multiple of any pyramid.
SHAPE = (3, 12, 18)


def shipped() -> list[tuple[str, str]]:
    """(method, preset) of every shipped weights file."""
    from tespike.golden.config import PRESETS
    from tespike.recon.learned import LEARNED, WEIGHTS_DIR, weights_name
    return [(method, preset) for preset in PRESETS for method in LEARNED
            if (WEIGHTS_DIR / weights_name(method, preset)).is_file()]


def stream(preset: str) -> np.ndarray:
    """Legal words of ``preset``, a third of the pixels dark (zero words: the head's one-spike bound)."""
    from tespike.golden.config import SensorConfig
    from tespike.golden.decode import legal_words
    rng = np.random.default_rng(7)
    words = rng.choice(legal_words(SensorConfig.preset(preset)), size=SHAPE)
    return np.where(rng.random(SHAPE) < 0.33, 0, words).astype(np.uint8)


def images(method: str, preset: str, words: np.ndarray) -> np.ndarray:
    import torch

    from tespike.golden.config import SensorConfig
    from tespike.recon.methods import reconstruct
    torch.set_num_threads(1)
    return reconstruct(words, SensorConfig.preset(preset), method)


def write() -> None:
    out = {}
    for method, preset in shipped():
        out.setdefault(f"words/{preset}", stream(preset))
        out[f"{method}/{preset}"] = images(method, preset, out[f"words/{preset}"])
    np.savez_compressed(REFERENCE, **out)
    print(f"wrote {REFERENCE}: {', '.join(k for k in out if not k.startswith('words/'))}")


@pytest.mark.parametrize("method, preset", shipped())
def test_shipped_weights_reconstruct_as_their_reference(method, preset, one_torch_thread):
    reference = np.load(REFERENCE)
    assert f"{method}/{preset}" in reference, f"no reference for {method} {preset}: write it (module docstring)"
    got = images(method, preset, reference[f"words/{preset}"])
    want = reference[f"{method}/{preset}"]
    assert got.shape == want.shape == SHAPE and float(want.std()) > 0
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python3 tests/test_recon_shipped_weights.py --write")
    write()
