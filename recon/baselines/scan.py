"""A selective state-space scan (Mamba) in plain torch, chunked so the sequence is processed in parallel.

The official Mamba kernels are compiled CUDA extensions (``mamba_ssm``,
``causal_conv1d``) that do not build for a CPU-first project; so the scan is
written here. The recurrence is Mamba's selective SSM,
``h_t = exp(dt_t A) h_{t-1} + dt_t B_t x_t``, ``y_t = C_t . h_t + D x_t``,
with input-dependent dt, B, C. Its decay is one scalar per head (the
restriction of Mamba-2's state-space duality, Dao & Gu 2024), which lets the
scan run in the chunked form of that paper: inside a chunk of ``chunk``
steps every output is a masked, decay-weighted sum over the chunk's inputs
(a small matrix product, all steps at once); between chunks only the state
is carried, one step per chunk. Inside a chunk the decay factors into
exp(cum_t) exp(-cum_s), so a chunk is one small matrix product; for that to
stay inside float32 the log-decay of one step is clamped to at least
-60 / chunk (a decay of at least 0.01 per step at the chunk of 13 used here:
a state forgotten that fast is already negligible). The sequential
recurrence, :func:`selective_scan_reference`, is the test's reference.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn


#: Largest total log-decay inside one chunk: exp(+-SPAN) stays far inside float32's range.
SPAN = 60.0


def selective_scan(u: torch.Tensor, log_decay: torch.Tensor, b: torch.Tensor, c: torch.Tensor,
                   chunk: int) -> torch.Tensor:
    """y_t = sum_{s <= t} C_t . B_s exp(sum_{s < r <= t} log_decay_r) u_s, chunk by chunk.

    u: (Z, L, H, P) inputs (already scaled by dt); log_decay: (Z, L, H), in
    [-SPAN / chunk, 0] (:class:`SelectiveSSM` clamps it); b, c: (Z, L, N).
    -> (Z, L, H, P). Inside a chunk the decay from s to t factors as
    exp(cum_t) exp(-cum_s) (cum: the log-decay summed from the chunk's start,
    within [-SPAN, 0]), so the chunk is one masked (T x T) matrix C B^T times
    the rescaled inputs: O(T) exponentials, no (T x T x H) tensor.
    """
    z, length, heads, p = u.shape
    n = b.shape[-1]
    k = -(-length // chunk)
    pad = k * chunk - length
    if pad:           # trailing steps with no input and no decay: the causal outputs are unchanged
        u = F.pad(u, (0, 0, 0, 0, 0, pad))
        log_decay = F.pad(log_decay, (0, 0, 0, pad))
        b = F.pad(b, (0, 0, 0, pad))
        c = F.pad(c, (0, 0, 0, pad))
    u = u.reshape(z, k, chunk, heads, p)
    b = b.reshape(z, k, chunk, n)
    c = c.reshape(z, k, chunk, n)
    cum = log_decay.reshape(z, k, chunk, heads).cumsum(2)                       # (Z, K, T, H), in [-SPAN, 0]
    causal = torch.ones(chunk, chunk, dtype=torch.bool, device=u.device).tril()
    scores = torch.einsum("zktn,zksn->zkts", c, b).masked_fill(~causal, 0.0)   # (Z, K, T, S)
    rising = cum.exp()[..., None]                                              # exp(cum_t)
    scaled = (u / rising).reshape(z, k, chunk, heads * p)                      # exp(-cum_s) u_s
    y = torch.matmul(scores, scaled).reshape(z, k, chunk, heads, p) * rising   # inside each chunk
    tail = (cum[:, :, -1:] - cum).exp()                                         # decay to the chunk's end
    gathered = torch.matmul(b.transpose(2, 3), (u * tail[..., None]).reshape(z, k, chunk, heads * p))
    gathered = gathered.reshape(z, k, n, heads, p)                              # state each chunk adds
    through = cum[:, :, -1].exp()                                               # (Z, K, H)
    state = u.new_zeros(z, n, heads, p)
    entering = []
    for i in range(k):                                                          # one step per chunk
        entering.append(state)
        state = through[:, i, None, :, None] * state + gathered[:, i]
    entering = torch.stack(entering, 1).reshape(z, k, n, heads * p)             # (Z, K, N, H P)
    y = y + torch.matmul(c, entering).reshape(z, k, chunk, heads, p) * rising
    return y.reshape(z, k * chunk, heads, p)[:, :length]


def selective_scan_reference(u, log_decay, b, c):
    """The same recurrence, one step at a time (the test's reference)."""
    z, length, heads, p = u.shape
    state = u.new_zeros(z, heads, b.shape[-1], p)
    out = []
    for t in range(length):
        state = log_decay[:, t, :, None, None].exp() * state + b[:, t, None, :, None] * u[:, t, :, None, :]
        out.append(torch.einsum("zn,zhnp->zhp", c[:, t], state))
    return torch.stack(out, 1)


class SelectiveSSM(nn.Module):
    """One direction of Mamba's SSM on (Z, L, D) sequences: input-dependent dt, B, C; decay per head."""

    def __init__(self, inner: int, state: int, head_dim: int, chunk: int):
        super().__init__()
        self.heads, self.head_dim, self.state, self.chunk = inner // head_dim, head_dim, state, chunk
        self.project = nn.Linear(inner, self.heads + 2 * state, bias=False)
        # dt initialised in [1e-3, 1e-1] as Mamba; A = -exp(a_log) in [1, 16]
        dt = torch.exp(torch.rand(self.heads) * (math.log(0.1) - math.log(1e-3)) + math.log(1e-3))
        self.dt_bias = nn.Parameter(dt + torch.log(-torch.expm1(-dt)))
        self.a_log = nn.Parameter(torch.log(torch.linspace(1.0, 16.0, self.heads)))
        self.skip = nn.Parameter(torch.ones(inner))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        z, length, d = x.shape
        dt_raw, b, c = self.project(x).split((self.heads, self.state, self.state), dim=-1)
        dt = F.softplus(dt_raw + self.dt_bias)                                  # (Z, L, H)
        log_decay = (-dt * self.a_log.exp()).clamp(min=-SPAN / self.chunk)     # decay >= e^-4.6 per step at 13
        u = x.reshape(z, length, self.heads, self.head_dim) * dt[..., None]
        y = selective_scan(u, log_decay, b, c, self.chunk).reshape(z, length, d)
        return y + x * self.skip


class MambaBlock(nn.Module):
    """Pre-norm bidirectional Mamba block on (Z, L, C) sequences (Vision Mamba's two directions).

    x + out(SiLU(gate) * (forward SSM + backward SSM)(SiLU(depthwise conv1d(in(x))))).
    """

    def __init__(self, channels: int, expand: int, state: int, head_dim: int, chunk: int, conv: int = 3):
        super().__init__()
        inner = expand * channels
        self.norm = nn.LayerNorm(channels)
        self.inp = nn.Linear(channels, 2 * inner)
        self.conv = nn.Conv1d(inner, inner, conv, padding=conv // 2, groups=inner)
        self.forward_ssm = SelectiveSSM(inner, state, head_dim, chunk)
        self.backward_ssm = SelectiveSSM(inner, state, head_dim, chunk)
        self.out = nn.Linear(inner, channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, gate = self.inp(self.norm(x)).chunk(2, dim=-1)
        h = F.silu(self.conv(h.transpose(1, 2)).transpose(1, 2))
        y = self.forward_ssm(h) + self.backward_ssm(h.flip(1)).flip(1)
        return x + self.out(y * F.silu(gate))
