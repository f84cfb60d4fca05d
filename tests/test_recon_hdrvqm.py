"""tespike.recon.hdrvqm: HDR-VQM equals a hand-written numpy reading of the steps; orders known distortions."""

import math

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter

from tespike.golden.errors import InputError
from tespike.recon import hdrvqm
from tespike.recon.display import HdrDisplay
from tespike.recon.metrics import PU21_BANDING_GLARE
from tespike.recon.scenes import make_scene


@pytest.fixture(autouse=True)
def one_torch_thread():
    """One torch thread: on the shared 2-core machine two threads contend badly (10-40x slower)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def numpy_hdr_vqm_frame(estimate, reference, peak, nits=4000.0, black=0.03, block=64):
    """One frame's HDR-VQM written the reference's way (Kovesi's centred filter layout, loops over blocks)."""
    def pu21(y):
        p0, p1, p2, p3, p4, p5, p6 = PU21_BANDING_GLARE
        y = np.clip(y, 0.005, 10000.0) ** p3
        return np.maximum(p6 * (((p0 + p1 * y) / (1 + p2 * y)) ** p4 - p5), 0)

    def shown(light):
        return pu21(np.clip(light * nits / peak, black, nits))

    rows, cols = reference.shape
    x = np.ones((rows, 1)) * (np.arange(cols) - cols / 2) / (cols / 2)
    y = ((np.arange(rows) - rows / 2) / (rows / 2))[:, None] * np.ones((1, cols))
    radius = np.hypot(x, y)
    radius[rows // 2, cols // 2] = 1
    theta = np.arctan2(y, x)
    sigma_theta = np.pi / 4 / 1.5
    fr, fe = np.fft.fft2(shown(reference)), np.fft.fft2(shown(estimate))
    total = np.zeros((rows, cols))
    for o in range(4):
        angle = o * np.pi / 4
        ds = np.sin(theta) * np.cos(angle) - np.cos(theta) * np.sin(angle)
        dc = np.cos(theta) * np.cos(angle) + np.sin(theta) * np.sin(angle)
        spread = np.exp(-np.abs(np.arctan2(ds, dc)) ** 2 / (2 * sigma_theta ** 2))
        for s in range(5):
            rfo = (1 / (3 * 3 ** s)) / 0.5
            lg = np.exp(-np.log(radius / rfo) ** 2 / (2 * np.log(0.55) ** 2))
            lg[rows // 2, cols // 2] = 0
            filt = np.fft.ifftshift(lg * spread)      # centre to the corner (MATLAB's fftshift, even sizes)
            a, b = np.abs(np.fft.ifft2(fr * filt)), np.abs(np.fft.ifft2(fe * filt))
            total += (2 * a * b + 0.2) / (a * a + b * b + 0.2)
    stds = [np.std(total[r:r + block, c:c + block], ddof=1)
            for r in range(0, rows, block) for c in range(0, cols, block)]
    keep = 1 + math.floor((len(stds) - 1) * 0.3 + 0.5)
    return float(np.mean(np.sort(stds)[:keep]))


def scene(frames=16, height=96, width=128):
    return make_scene("city", frames=frames, height=height, width=width).astype(np.float64)


def test_equal_to_numpy_reading_of_the_steps(rng):
    ref = scene(frames=2, height=70, width=132)      # partial edge blocks in both directions
    est = ref * rng.lognormal(0, 0.1, ref.shape)
    per_frame = hdrvqm.hdr_vqm(est, ref)
    peak = float(ref.max())
    expected = [numpy_hdr_vqm_frame(est[k], ref[k], peak) for k in range(2)]
    assert np.allclose(per_frame, expected, rtol=1e-9)
    assert hdrvqm.hdr_vqm(est[1], ref[1], peak=peak).shape == ()


def test_identical_is_zero_at_any_size():
    ref = scene(frames=3, height=70, width=90)
    assert np.array_equal(hdrvqm.hdr_vqm(ref, ref), np.zeros(3))
    assert hdrvqm.hdr_vqm_video(ref, ref) == 0.0


def test_orders_noise_and_blur(rng):
    ref = scene()
    noise = rng.standard_normal(ref.shape)
    cases = [ref] + [ref * (1 + s * noise) for s in (0.02, 0.1, 0.3)] + [gaussian_filter(ref, (0, 3, 3))]
    scores = [hdrvqm.hdr_vqm_scores(c, ref) for c in cases]
    per_frame = [float(s[0].mean()) for s in scores]
    video = [s[1] for s in scores]
    assert per_frame[0] == 0 and all(np.diff(per_frame) > 0), per_frame   # identical < noise < ... < blur
    assert video[0] == 0 and all(np.diff(video) > 0), video
    blurs = [hdrvqm.hdr_vqm(gaussian_filter(ref, (0, s, s)), ref).mean() for s in (0.7, 1.5, 3.0)]
    assert all(np.diff(blurs) > 0), blurs


def test_display_grading_from_the_reference(rng):
    ref = scene(frames=2)
    est = ref * rng.lognormal(0, 0.05, ref.shape)
    base = hdrvqm.hdr_vqm(est, ref)
    assert np.allclose(hdrvqm.hdr_vqm(est * 7, ref * 7), base, rtol=1e-9)     # scene units do not matter
    assert np.all(hdrvqm.hdr_vqm(ref * 0.5, ref) > 0)                         # a gain error is seen
    dim = hdrvqm.hdr_vqm(est, ref, display=HdrDisplay(peak_nits=100.0, black_nits=0.1))
    assert not np.allclose(dim, base)                                          # the display matters


def test_tubes_and_pooling():
    errors = torch.from_numpy(np.random.default_rng(0).normal(size=(3, 70, 130)))
    n, mean, m2 = hdrvqm.combine_statistics(*hdrvqm.block_statistics(errors, hdrvqm.BLOCK))
    devs = (m2 / (n - 1)).sqrt()                                   # each tube's sample deviation
    e = errors.numpy()
    expected = [np.std(e[:, r:r + 64, c:c + 64], ddof=1) for r in (0, 64) for c in (0, 64, 128)]
    assert np.allclose(devs.numpy(), expected, rtol=1e-12)
    values = torch.arange(10, 0, -1, dtype=torch.float64)          # keep 1 + round(9 * 0.3) = 4 lowest
    assert hdrvqm.lowest_mean(values).item() == pytest.approx(2.5)
    # a sequence of 20 frames has one full fixation of 15 frames; 5 frames make none
    ref = scene(frames=20, height=64, width=64)
    est = ref.copy()
    est[15:] *= 0.5                                                # only the frames past the fixation
    assert hdrvqm.hdr_vqm_video(est, ref) == 0.0
    assert np.all(hdrvqm.hdr_vqm(est, ref)[15:] > 0)


def test_refused_up_front_when_memory_is_short(monkeypatch):
    import tespike.golden.resources
    from tespike import golden
    monkeypatch.setattr(golden.resources, "available_memory", lambda: 1 << 20)
    ref = scene(frames=1, height=64, width=96)
    with pytest.raises(InputError, match="HDR-VQM of 64 x 96 frames needs about"):
        hdrvqm.hdr_vqm(ref, ref)


def test_refusals(rng):
    ref = scene(frames=2, height=32, width=32)
    with pytest.raises(InputError, match="shape"):
        hdrvqm.hdr_vqm(ref[:, 1:], ref)
    with pytest.raises(InputError, match="all zero"):
        hdrvqm.hdr_vqm(ref, np.zeros_like(ref))
    with pytest.raises(InputError, match="negative"):
        hdrvqm.hdr_vqm(ref, ref - 0.5)
    bad = ref.copy()
    bad[0, 0, 0] = np.inf
    with pytest.raises(InputError, match="non-finite"):
        hdrvqm.hdr_vqm(bad, ref)
    with pytest.raises(InputError, match="peak"):
        hdrvqm.hdr_vqm(ref, ref, peak=-1.0)
    with pytest.raises(InputError, match="black"):
        HdrDisplay(peak_nits=1.0, black_nits=2.0)


@pytest.mark.parametrize("shape", [(1, 1), (2, 8), (8, 3)])
def test_frames_too_small_for_a_deviation_are_refused(shape):
    """A 1 x 1 estimate at 1 % of its reference scored 0 ("identical")."""
    reference = np.ones((2, *shape), np.float32)
    with pytest.raises(InputError, match=r"HDR-VQM needs frames of at least 4 x 4 pixels"):
        hdrvqm.hdr_vqm(reference * 0.01, reference)
