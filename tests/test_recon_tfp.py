"""tespike.recon.tfp: windowed mean of decoded light, truncated at the stream ends."""

import pytest
import torch

from tespike.recon.tfp import tfp


def test_hand_worked_radius_1():
    light = torch.tensor([1.0, 2.0, 4.0, 8.0, 16.0], dtype=torch.float64)
    assert tfp(light, 1).tolist() == [1.5, 7 / 3, 14 / 3, 28 / 3, 12.0]


def test_hand_worked_radius_2_two_pixels():
    light = torch.tensor([[0.0, 3.0], [0.0, 3.0], [5.0, 3.0], [0.0, 3.0]], dtype=torch.float64)
    out = tfp(light, 2)
    assert out[:, 0].tolist() == [5 / 3, 5 / 4, 5 / 4, 5 / 3]
    assert out[:, 1].tolist() == [3.0] * 4
    assert out.dtype == torch.float64


def test_radius_0_is_identity_and_window_wider_than_stream_is_the_mean():
    light = torch.rand(7, 3, 2, dtype=torch.float64)
    assert torch.equal(tfp(light, 0), light)
    assert torch.allclose(tfp(light, 3), tfp(light[:, None], 3)[:, 0])
    assert torch.allclose(tfp(light, 50), light.mean(0, keepdim=True).expand_as(light))


def test_keeps_float32():
    light = torch.tensor([1.0, 2.0, 4.0])
    assert tfp(light, 1).dtype == torch.float32
    assert tfp(light, 1).tolist() == pytest.approx([1.5, 7 / 3, 3.0], rel=1e-7)


def test_empty_stream():
    assert tfp(torch.zeros(0, 2, 2), 4).shape == (0, 2, 2)


def test_shifted_sums_equal_cumulative_sums():
    light = torch.rand(80, 5, dtype=torch.float64)
    for radius in (1, 4, 16, 17, 30):
        ref = torch.stack([light[max(0, k - radius):k + radius + 1].mean(0) for k in range(80)])
        assert torch.allclose(tfp(light, radius), ref, rtol=1e-12, atol=0), radius


def test_dark_readouts_after_bright_ones_keep_their_precision():
    light = torch.cat([torch.full((5000, 1), 2.0, dtype=torch.float64),
                       torch.full((20, 1), 1e-5, dtype=torch.float64)])
    assert tfp(light, 4)[-1, 0].item() == pytest.approx(1e-5, rel=1e-12)


def test_a_wide_window_on_float32_light_keeps_a_dim_present_after_a_bright_past():
    """Windows past SHIFTED_SUM_MAX_WINDOW use a cumulative sum: in float32, after 1e5 bright readouts,
    a pixel at 4.2e-4 read 2.2e-4 (-37 %); the same words without the bright past read right."""
    dim = torch.zeros(200, 1)
    dim[50::10] = 1.0 / 240
    light = torch.cat([torch.ones(100_000, 1), dim])
    for radius in (17, 20):                   # (33 readouts: shifted sums; 41: the cumulative sum)
        wide = tfp(light, radius)
        assert wide.dtype == torch.float32
        assert torch.allclose(wide[-150:-100], tfp(dim, radius)[50:100], rtol=1e-6, atol=0), radius


@pytest.mark.parametrize("radius", [-1, 2.5, True, "3"])
def test_a_radius_that_is_no_count_is_refused_in_one_line(radius):
    """A radius of -1 had given TFP the light negated (a window of -1 readouts counted) and TFI
    a search shifted past the readout itself."""
    from tespike.golden.errors import InputError
    from tespike.recon.tfi import tfi
    light = torch.rand(5, 2, 3)
    for run in (lambda: tfp(light, radius), lambda: tfi(light, light > 0.5, 0.1, radius, search="window")):
        with pytest.raises(InputError, match=f"^window radius {radius!r}: must be an integer >= 0$"):
            run()
