"""tespike.recon.fovvideovdp: pyfvvdp imports beside torch 2.13, runs offline, and orders known distortions."""

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter

from tespike.golden.errors import InputError
from tespike.recon.display import HdrDisplay
from tespike.recon.fovvideovdp import fovvideovdp
from tespike.recon.scenes import make_scene


@pytest.fixture(autouse=True)
def one_torch_thread():
    """One torch thread: on the shared 2-core machine two threads contend badly."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def scene(frames=2, height=64, width=96):
    return make_scene("city", frames=frames, height=height, width=width).astype(np.float64)


def test_pinned_torch_unchanged():
    import pyfvvdp
    assert torch.__version__.startswith("2.13.0")
    assert pyfvvdp.fvvdp is not None


def test_identical_is_ten_jod_and_distortions_are_ordered(rng):
    ref = scene()
    assert np.allclose(fovvideovdp(ref, ref), 10.0, atol=1e-4)
    noise = rng.standard_normal(ref.shape)
    cases = [ref * (1 + s * noise) for s in (0.02, 0.1, 0.3)] + [gaussian_filter(ref, (0, 3, 3))]
    jod = [float(fovvideovdp(c, ref).mean()) for c in cases]
    assert 10.0 > jod[0] and all(np.diff(jod) < 0), jod        # slight noise > ... > blur
    blurs = [float(fovvideovdp(gaussian_filter(ref, (0, s, s)), ref).mean()) for s in (0.7, 1.5, 3.0)]
    assert all(np.diff(blurs) < 0), blurs


def test_display_grading_from_the_reference(rng):
    ref = scene(frames=1)
    est = ref * rng.lognormal(0, 0.1, ref.shape)
    base = fovvideovdp(est, ref)
    assert np.allclose(fovvideovdp(est * 7, ref * 7), base, atol=1e-4)      # scene units do not matter
    assert fovvideovdp(ref * 0.5, ref)[0] < 10.0                          # a gain error is seen
    dim = fovvideovdp(est, ref, display=HdrDisplay(peak_nits=10.0, black_nits=0.1))
    assert not np.allclose(dim, base)
    assert fovvideovdp(est[0], ref[0]).shape == ()


def test_refused_up_front_when_memory_is_short(monkeypatch):
    import tespike.golden.resources
    from tespike import golden
    monkeypatch.setattr(golden.resources, "available_memory", lambda: 1 << 20)
    ref = scene(frames=1)
    with pytest.raises(InputError, match="FovVideoVDP of 64 x 96 frames needs about"):
        fovvideovdp(ref, ref)


def test_refusals():
    ref = scene(frames=1, height=16, width=16)
    with pytest.raises(InputError, match="shape"):
        fovvideovdp(ref[:, 1:], ref)
    with pytest.raises(InputError, match="all zero"):
        fovvideovdp(ref, np.zeros_like(ref))
    with pytest.raises(InputError, match="negative"):
        fovvideovdp(ref, ref - 0.5)
    with pytest.raises(InputError, match="non-finite"):
        fovvideovdp(ref * np.nan, ref)


@pytest.mark.parametrize("shape", [(2, 2), (3, 32), (32, 3)])
def test_frames_pyfvvdp_cannot_judge_are_refused_in_one_line(shape):
    """Frames of 2 or 3 pixels on a side ended in pyfvvdp's AttributeError traceback."""
    reference = np.ones((2, *shape), np.float32)
    with pytest.raises(InputError, match=r"FovVideoVDP needs frames of at least 4 x 4 pixels"):
        fovvideovdp(reference * 0.5, reference)
