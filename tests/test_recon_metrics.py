"""tespike.recon.metrics: torch PSNR-mu / SSIM-mu equal scikit-image on the same tone-mapped images."""

import math

import numpy as np
import pytest
import torch
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from tespike.golden.errors import InputError
from tespike.recon import metrics


def hdr_pair(rng, shape=(3, 24, 31)):
    """Ground truth over five decades and a noisy, slightly biased prediction."""
    gt = 10 ** rng.uniform(-5, 0, size=shape)
    pred = gt * rng.lognormal(0.05, 0.3, size=shape)
    return pred, gt


def skimage_mu(pred, gt, mu=5000):
    out_p, out_s = [], []
    for p, g in zip(pred, gt):
        peak = g.max()
        tp = np.log1p(mu * np.clip(p / peak, 0, 1)) / np.log1p(mu)
        tg = np.log1p(mu * np.clip(g / peak, 0, 1)) / np.log1p(mu)
        out_p.append(peak_signal_noise_ratio(tg, tp, data_range=1))
        out_s.append(structural_similarity(tg, tp, gaussian_weights=True, sigma=1.5,
                                           use_sample_covariance=False, data_range=1))
    return np.array(out_p), np.array(out_s)


def test_equal_to_scikit_image(rng):
    pred, gt = hdr_pair(rng)
    ref_psnr, ref_ssim = skimage_mu(pred, gt)
    assert np.allclose(metrics.psnr_mu(pred, gt), ref_psnr, rtol=1e-12, atol=0)
    assert np.allclose(metrics.ssim_mu(pred, gt), ref_ssim, rtol=1e-10, atol=1e-12)
    # torch tensors, float32 and single frames give the same
    assert np.allclose(metrics.ssim_mu(torch.from_numpy(pred), torch.from_numpy(gt)), ref_ssim, rtol=1e-10)
    assert metrics.psnr_mu(pred[1], gt[1]).shape == ()
    assert metrics.psnr_mu(pred[1], gt[1]) == pytest.approx(ref_psnr[1], rel=1e-12)


def test_ssim_smallest_frame_equal_to_scikit_image(rng):
    pred, gt = hdr_pair(rng, (2, 11, 11))
    assert np.allclose(metrics.ssim_mu(pred, gt), skimage_mu(pred, gt)[1], rtol=1e-10)
    with pytest.raises(InputError, match="at least 11 x 11"):
        metrics.ssim_mu(pred[:, :10], gt[:, :10])


def test_normalised_by_ground_truth_peak_not_min_max(rng):
    _, gt = hdr_pair(rng)
    assert np.all(np.isinf(metrics.psnr_mu(gt, gt)))
    assert np.allclose(metrics.ssim_mu(gt, gt), 1)
    # a prediction at half the light is penalised (a min-max normalisation would hide it)
    assert np.all(metrics.psnr_mu(gt / 2, gt) < 30)
    # one peak for the whole sequence: scaling both by it changes nothing
    assert np.allclose(metrics.psnr_mu(gt * 7, gt * 7, peak=7.0 * gt.max()),
                       metrics.psnr_mu(gt, gt, peak=gt.max()))


def test_prediction_clipped_to_ground_truth_peak(rng):
    _, gt = hdr_pair(rng)
    over = gt.copy()
    over[gt == gt.max()] *= 1e6            # far above the peak: clipped to it
    assert np.all(np.isinf(metrics.psnr_mu(over, gt)))
    # negative predicted light is clipped to 0: equal to a black ground truth
    assert np.all(np.isinf(metrics.psnr_mu(np.full_like(gt, -5.0), np.zeros_like(gt), peak=1.0)))


def test_hand_worked_psnr_mu():
    gt = np.ones((1, 4, 4))
    pred = np.zeros((1, 4, 4))           # T(0) = 0, T(1) = 1: mse 1 -> 0 dB
    assert metrics.psnr_mu(pred, gt)[0] == pytest.approx(0.0, abs=1e-12)
    half = np.full((1, 4, 4), 0.5)
    t = math.log1p(2500) / math.log1p(5000)
    assert metrics.psnr_mu(half, gt)[0] == pytest.approx(-20 * math.log10(1 - t), rel=1e-12)


def test_pu21():
    y = torch.tensor([0.005, 100.0, 10000.0, 1e6], dtype=torch.float64)
    v = metrics.pu21_encode(y)
    assert v[0].item() == pytest.approx(0, abs=1e-6)
    assert v[1].item() == pytest.approx(256.4, abs=0.5)       # 100 cd/m^2 ~ 256 by design
    assert v[3].item() == v[2].item()                         # clamped at 10000 cd/m^2
    gt = np.full((2, 3, 3), 0.025)                            # 100 cd/m^2 at 4000 per unit
    pred = gt * 1.1
    p0, p1, p2, p3, p4, p5, p6 = metrics.PU21_BANDING_GLARE
    enc = lambda y: p6 * (((p0 + p1 * y ** p3) / (1 + p2 * y ** p3)) ** p4 - p5)
    expected = 20 * math.log10(256 / abs(enc(110.0) - enc(100.0)))
    assert np.allclose(metrics.psnr_pu21(pred, gt), expected, rtol=1e-12)
    # the luminance scale matters: the same relative error at 1000x lower light
    assert metrics.psnr_pu21(pred, gt, nits_per_unit=4.0)[0] != pytest.approx(expected)
    with pytest.raises(InputError, match="nits_per_unit"):
        metrics.psnr_pu21(pred, gt, nits_per_unit=0)


def test_refusals(rng):
    pred, gt = hdr_pair(rng)
    with pytest.raises(InputError, match="shape"):
        metrics.psnr_mu(pred[:, 1:], gt)
    with pytest.raises(InputError, match="frame 1 is all zero"):
        gt0 = gt.copy(); gt0[1] = 0
        metrics.psnr_mu(pred, gt0)
    with pytest.raises(InputError, match="non-finite"):
        p = pred.copy(); p[0, 0, 0] = np.nan
        metrics.ssim_mu(p, gt)
    with pytest.raises(InputError, match="negative"):
        metrics.psnr_mu(pred, -gt)
    with pytest.raises(InputError, match="peak"):
        metrics.psnr_mu(pred, gt, peak=0.0)
    with pytest.raises(InputError, match="ground truth would be clipped"):
        metrics.ssim_mu(pred, gt, peak=0.5 * float(gt.max()))
    with pytest.raises(InputError, match=r"\(K, H, W\)"):
        metrics.psnr_mu(pred[0, 0], gt[0, 0])
    for mu in (-1.0, 0, float("nan"), float("inf"), True):            # (-1 had been 'math domain error')
        for metric in (metrics.psnr_mu, metrics.ssim_mu):
            with pytest.raises(InputError, match="mu = .*the mu-law constant"):
                metric(pred, gt, mu=mu)


def test_nested_lists_are_frames_and_what_is_no_number_is_refused():
    """As a library caller may pass them: lists were 'list indices must be integers' (a TypeError);
    an object array torch's TypeError; a bool array is refused as before, now before torch sees it."""
    frame = [[0.5, 1.0, 2.0, 4.0]] * 12
    assert metrics.psnr_mu(frame, frame) == metrics.psnr_mu(np.array(frame), np.array(frame))
    assert metrics.psnr_pu21(frame, frame) == metrics.psnr_pu21(np.array(frame), np.array(frame))
    square = np.linspace(0.1, 2.0, 144).reshape(12, 12)
    assert metrics.ssim_mu(square.tolist(), square.tolist()) == pytest.approx(1.0)
    for bad, dtype in (([[None, 1.0]], "object"), ([[True, False]], "bool"), ([[1j, 2.0]], "complex128")):
        with pytest.raises(InputError, match=f"^prediction dtype {dtype} is not a real number type$"):
            metrics.psnr_mu(bad, [[1.0, 2.0]])


def test_twelve_decades_and_huge_light(rng):
    gt = 10 ** rng.uniform(-12, 0, size=(2, 16, 16))
    pred = gt * 1.01
    ref_psnr, ref_ssim = skimage_mu(pred, gt)
    assert np.allclose(metrics.psnr_mu(pred, gt), ref_psnr, rtol=1e-12)
    assert np.allclose(metrics.ssim_mu(pred, gt), ref_ssim, rtol=1e-10)
    # scale invariance up to 1e30 x: only the ratio to the peak matters
    assert np.allclose(metrics.psnr_mu(pred * 1e30, gt * 1e30), ref_psnr, rtol=1e-9)
    # PU21 clamps at 10000 cd/m^2: two images both far above it are equal
    assert np.all(np.isinf(metrics.psnr_pu21(pred * 1e30, gt * 1e30)))


def test_one_mu_law_for_metrics_pictures_and_learned_methods():
    """One constant mu and one torch mu-law (recon.mulaw.compress) serve the metrics;
    the numpy tone map of the pictures is its twin for code that runs without torch."""
    from tespike.recon import mulaw
    from tespike.recon.mulaw import compress
    h = torch.linspace(0, 1, 101, dtype=torch.float64)
    assert torch.equal(metrics.mu_law(h), compress(h, mulaw.MU))
    assert np.allclose(mulaw.tone_map(h.numpy(), 1.0), metrics.mu_law(h).numpy(), rtol=0, atol=1e-15)
    # a tiny mu tends to the identity, a subnormal one too (it drew black below half the peak, white above)
    for mu in (1e-300, 5e-324):
        assert np.allclose(mulaw.tone_map(h.numpy(), 1.0, mu), h.numpy(), rtol=0, atol=1e-15)
    # the in-place twin the baselines use on their large firing-rate stacks
    from tespike.recon.mulaw import compress_
    light = torch.cat((torch.tensor([-0.5, 0.0]), torch.logspace(-6, 1, 50)))
    work = light.clone()
    assert compress_(work, 5000.0) is work and torch.equal(work, compress(light, 5000.0))


def test_the_mu_law_refuses_a_mu_peak_or_light_it_cannot_map_in_one_line():
    """mu = 0 had made every code NaN and mu = -1 was math's "domain error"; tone_map drew a flat
    picture for a peak of 0, -1 or NaN and dropped a complex light's imaginary part with a warning;
    a numpy array in the torch functions was an AttributeError of ``clamp``."""
    from tespike.golden.errors import InputError
    from tespike.recon.mulaw import compress, compress_, expand, tone_map
    for mu in (0, -1, float("nan"), "5000", True):
        for call in (lambda: compress(torch.ones(2), mu), lambda: compress_(torch.ones(2), mu),
                     lambda: expand(torch.ones(2), mu), lambda: tone_map(np.ones(2), 1.0, mu)):
            with pytest.raises(InputError, match=f"^mu-law mu {mu!r}: must be a finite number > 0"):
                call()
    for peak in (0, -1.0, float("nan"), None):
        with pytest.raises(InputError, match=f"^tone map peak {peak!r}: must be a finite number > 0$"):
            tone_map(np.ones(2), peak)
    with pytest.raises(InputError, match="^tone map light: dtype complex128 is not real numbers$"):
        tone_map(np.array([1j]), 1.0)
    with pytest.raises(InputError, match="^mu-law light: must be a torch tensor, not ndarray"):
        compress(np.ones(2), 5000.0)


def test_the_metrics_refuse_devices_displays_and_frames_they_cannot_score_in_one_line():
    """A device torch cannot use was its AssertionError or RuntimeError, a display's name an
    AttributeError, a ragged list numpy's "inhomogeneous shape", a tensor that requires grad
    numpy()'s RuntimeError, frames of no pixel range()'s "arg 3 must not be zero", a stack beside
    one frame was paired silently, and ``nits_per_unit=True`` taken while numpy's float32 was refused."""
    from tespike.recon.fovvideovdp import fovvideovdp
    from tespike.recon.hdrvqm import hdr_vqm
    a = np.random.default_rng(0).random((2, 16, 16)) + 0.1
    for device, words in (("cuda:7", "not a usable torch device"), ("xyz", "not a usable torch device"),
                          ("meta", "the meta device holds no data")):
        for metric in (metrics.psnr_mu, metrics.ssim_mu, metrics.psnr_pu21, hdr_vqm, fovvideovdp):
            with pytest.raises(InputError, match=f"^device = '{device}': {words}"):
                metric(a, a, device=device)
    for metric in (hdr_vqm, fovvideovdp):
        with pytest.raises(InputError, match="^display = 'sim2': must be an HdrDisplay"):
            metric(a, a, display="sim2")
    with pytest.raises(InputError, match=r"^light given as a list must be numbers arranged as \(K, H, W\)"):
        metrics.psnr_mu([[1, 2], [3]], [[1, 2], [3]])
    assert metrics.psnr_mu(torch.ones((2, 2), requires_grad=True), torch.ones((2, 2))) == math.inf
    with pytest.raises(InputError, match=r"^frames of shape \(2, 0, 3\) hold no pixel to score$"):
        metrics.psnr_pu21(np.ones((2, 0, 3)), np.ones((2, 0, 3)))
    with pytest.raises(InputError, match=r"^prediction shape \(1, 2, 2\) and ground truth shape \(2, 2\): both"):
        metrics.psnr_mu(np.ones((1, 2, 2)), np.ones((2, 2)))
    with pytest.raises(InputError, match="^nits_per_unit = True: must be a finite number > 0$"):
        metrics.psnr_pu21(a, a, nits_per_unit=True)
    assert np.isfinite(metrics.psnr_pu21(a * 0.9, a, nits_per_unit=np.float32(4000))).all()
