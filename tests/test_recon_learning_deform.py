"""tespike.recon.learning.deform: the plain-torch DCNv2 against conv2d and a direct float64 loop."""

import math

import pytest
import torch
import torch.nn.functional as F

from tespike.recon.learning.deform import ModulatedDeformConv2d, deform_conv2d


def deform_conv2d_loop(input, offset, weight, bias=None, *, stride=1, padding=0, dilation=1, mask=None):
    """Direct float64 reference of :func:`deform_conv2d`: one bilinear sample per
    output pixel, tap and channel, in Python loops (tests only; tiny inputs)."""
    input, offset, weight = input.double(), offset.double(), weight.double()
    n, c, h, w = input.shape
    c_out, _, kh, kw = weight.shape
    taps = kh * kw
    groups = offset.shape[1] // (2 * taps)
    h_out, w_out = offset.shape[2:]
    mask = torch.ones(n, groups * taps, h_out, w_out, dtype=torch.float64) if mask is None else mask.double()
    out = torch.zeros(n, c_out, h_out, w_out, dtype=torch.float64)

    def pixel(b, ch, y, x):
        return float(input[b, ch, y, x]) if 0 <= y < h and 0 <= x < w else 0.0

    def bilinear(b, ch, y, x):
        y0, x0 = math.floor(y), math.floor(x)
        fy, fx = y - y0, x - x0
        return ((1 - fy) * (1 - fx) * pixel(b, ch, y0, x0) + (1 - fy) * fx * pixel(b, ch, y0, x0 + 1)
                + fy * (1 - fx) * pixel(b, ch, y0 + 1, x0) + fy * fx * pixel(b, ch, y0 + 1, x0 + 1))

    per_group = c // groups
    for b in range(n):
        for oy in range(h_out):
            for ox in range(w_out):
                for i in range(kh):
                    for j in range(kw):
                        tap = i * kw + j
                        for ch in range(c):
                            g = ch // per_group
                            dy = float(offset[b, 2 * (g * taps + tap), oy, ox])
                            dx = float(offset[b, 2 * (g * taps + tap) + 1, oy, ox])
                            y = oy * stride - padding + i * dilation + dy
                            x = ox * stride - padding + j * dilation + dx
                            value = bilinear(b, ch, y, x) * float(mask[b, g * taps + tap, oy, ox])
                            out[b, :, oy, ox] += weight[:, ch, i, j] * value
    if bias is not None:
        out += bias.double().reshape(1, c_out, 1, 1)
    return out


def test_zero_offsets_and_unit_mask_equal_conv2d():
    g = torch.Generator().manual_seed(0)
    x = torch.randn(2, 6, 11, 13, generator=g, dtype=torch.float64)
    weight = torch.randn(5, 6, 3, 3, generator=g, dtype=torch.float64)
    bias = torch.randn(5, generator=g, dtype=torch.float64)
    offset = torch.zeros(2, 18, 11, 13, dtype=torch.float64)
    out = deform_conv2d(x, offset, weight, bias, padding=1)
    assert torch.allclose(out, F.conv2d(x, weight, bias, padding=1), atol=1e-12)


@pytest.mark.parametrize("kernel, stride, padding, dilation, groups", [
    (3, 1, 1, 1, 1), (3, 1, 1, 1, 2), (3, 2, 0, 2, 1), (1, 1, 0, 1, 1), (5, 1, 2, 1, 1)])
def test_equals_loop_reference(kernel, stride, padding, dilation, groups):
    g = torch.Generator().manual_seed(kernel * 10 + groups)
    n, c, h, w, c_out = 2, 4, 7, 8, 3
    x = torch.randn(n, c, h, w, generator=g, dtype=torch.float64)
    weight = torch.randn(c_out, c, kernel, kernel, generator=g, dtype=torch.float64)
    bias = torch.randn(c_out, generator=g, dtype=torch.float64)
    h_out = (h + 2 * padding - dilation * (kernel - 1) - 1) // stride + 1
    w_out = (w + 2 * padding - dilation * (kernel - 1) - 1) // stride + 1
    # offsets up to +-3 pixels reach past the frame: the zero outside must match too
    offset = 3 * torch.randn(n, 2 * groups * kernel ** 2, h_out, w_out, generator=g, dtype=torch.float64)
    mask = torch.rand(n, groups * kernel ** 2, h_out, w_out, generator=g, dtype=torch.float64)
    kw = dict(stride=stride, padding=padding, dilation=dilation, mask=mask)
    out = deform_conv2d(x, offset, weight, bias, **kw)
    ref = deform_conv2d_loop(x, offset, weight, bias, **kw)
    assert torch.allclose(out, ref, atol=1e-10), (out - ref).abs().max()


def test_offset_layout_is_dy_then_dx_per_tap():
    """A one-tap kernel with offset (dy, dx) = (1, 0) reads the pixel below."""
    x = torch.arange(20, dtype=torch.float64).reshape(1, 1, 4, 5)
    weight = torch.ones(1, 1, 1, 1, dtype=torch.float64)
    down = torch.zeros(1, 2, 4, 5, dtype=torch.float64)
    down[:, 0] = 1.0
    out = deform_conv2d(x, down, weight)
    assert torch.allclose(out[0, 0, :3], x[0, 0, 1:], atol=1e-9)
    assert torch.allclose(out[0, 0, 3], torch.zeros(5, dtype=torch.float64), atol=1e-9)   # below: zero


def test_gradients_match_finite_differences():
    g = torch.Generator().manual_seed(3)
    x = torch.randn(1, 2, 5, 5, generator=g, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(2, 2, 3, 3, generator=g, dtype=torch.float64, requires_grad=True)
    offset = (0.7 * torch.randn(1, 18, 5, 5, generator=g, dtype=torch.float64)).requires_grad_()
    mask = torch.rand(1, 9, 5, 5, generator=g, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b, c, d: deform_conv2d(a, c, b, padding=1, mask=d),
                                    (x, weight, offset, mask), atol=1e-6)


def test_module_shapes_and_refusals():
    layer = ModulatedDeformConv2d(8, 4, 3)
    x = torch.randn(2, 8, 9, 10)
    out = layer(x, torch.zeros(2, layer.offset_channels, 9, 10), torch.ones(2, layer.mask_channels, 9, 10))
    assert out.shape == (2, 4, 9, 10)
    with pytest.raises(ValueError, match="offset"):
        layer(x, torch.zeros(2, 5, 9, 10), torch.ones(2, 9, 9, 10))
