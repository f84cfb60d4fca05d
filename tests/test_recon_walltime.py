"""The run time every report gives: each timed call runs once (torch's ``Timer.timeit`` ran two more)."""

from __future__ import annotations

import math

import pytest

from tespike.recon.walltime import median_seconds


def test_each_repeat_calls_once_and_the_result_is_a_calls_own():
    calls = []
    seconds, result = median_seconds(lambda: calls.append(len(calls)) or len(calls), 3)
    assert len(calls) == 3 and result == 3 and seconds >= 0
    calls.clear()
    assert median_seconds(lambda: calls.append(1) or len(calls), 2, warm_up=True)[1] == 3 and len(calls) == 3


def test_the_median_not_the_mean():
    import time
    pauses = iter([0.0, 0.2, 0.0])
    seconds, _ = median_seconds(lambda: time.sleep(next(pauses)), 3)
    assert seconds < 0.1


def test_no_repeat_gives_nan_and_one_untimed_call():
    calls = []
    seconds, result = median_seconds(lambda: calls.append(1) or "r", 0)
    assert math.isnan(seconds) and result == "r" and len(calls) == 1


def test_the_small_recon_helpers_refuse_what_they_cannot_take_in_one_line(tmp_path):
    """median_seconds(f, 2.5) was a TypeError; the display's luminance of a numpy light an AttributeError
    and a peak of '1' math's TypeError; write_text of bytes pathlib's TypeError; save_figure(None) an
    AttributeError and dpi=0 matplotlib's ValueError; tile_seed(2.5, ...) was taken as 2."""
    import numpy as np
    import torch

    from tespike.golden.config import SensorConfig
    from tespike.golden.errors import InputError
    from tespike.recon.dataset.store import tile_seed
    from tespike.recon.display import HdrDisplay
    from tespike.recon.pictures import save_figure, write_text
    from tespike.recon.walltime import median_seconds
    with pytest.raises(InputError, match="^median_seconds repeats 2.5: must be an integer >= 0$"):
        median_seconds(lambda: 1, 2.5)
    with pytest.raises(InputError, match="^median_seconds: 3 is not a function to time$"):
        median_seconds(3, 1)
    with pytest.raises(InputError, match="^display luminance: the light must be a torch tensor, not ndarray$"):
        HdrDisplay().luminance(np.ones(2), 1.0)
    for peak in ("1", None, 0.0, float("nan")):
        with pytest.raises(InputError, match=f"^reference peak {peak!r}: must be a finite number > 0"):
            HdrDisplay().luminance(torch.ones(2), peak)
    assert HdrDisplay().luminance(torch.ones(1), torch.tensor(2.0)).item() > 0
    with pytest.raises(InputError, match="^write_text: the text must be a str, not bytes$"):
        write_text(tmp_path / "t.txt", b"x")
    with pytest.raises(InputError, match="^save_figure: NoneType is no matplotlib figure$"):
        save_figure(None, tmp_path / "f.png")
    from matplotlib.figure import Figure
    with pytest.raises(InputError, match="^save_figure dpi 0: must be a finite number > 0$"):
        save_figure(Figure(), tmp_path / "f.png", dpi=0)
    assert not list(tmp_path.iterdir())
    for seed in (2.5, -1):
        with pytest.raises(InputError, match=f"^tile_seed seed {seed!r}: must be an integer >= 0$"):
            tile_seed(seed, "a", SensorConfig(), 0, 0)
