# amaranth: UnusedElaboratable=no
import pytest
from amaranth.hdl import ClockDomain, Module
from amaranth.sim import Simulator

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError
from tespike.rtl.timing import ReadoutTiming
from tests.configs import EDGE_CONFIGS


def run_timing(config, clocks, reset_at=None):
    """(ccc, last, frame_valid) as sampled by each edge t = 0..clocks-1.

    The counters describe the clock the array's input register holds: sampled by
    edge t, they show clock t - 1 (clock -1, the last of an interval, at edge 0).

    With ``reset_at = r``, ``rst`` is high for the edge r and the count restarts at the next edge.
    ``ccc`` is None for ML (the ML timing has no CCC port).
    """
    top = Module()
    top.domains.sync = domain = ClockDomain("sync")
    top.submodules.dut = dut = ReadoutTiming(config)
    signals = [dut.last, dut.frame_valid, dut.ccc if config.is_te else dut.last]
    seen = []

    async def bench(ctx):
        for t in range(clocks):
            ctx.set(domain.rst, int(t == reset_at))
            _, _, last, valid, ccc = await ctx.tick().sample(*signals)
            seen.append((ccc if config.is_te else None, last, valid))

    sim = Simulator(top)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return seen


def expected(config, t):
    """SPEC section 1: CCC value c = j + 1 and the S_r strobe of pixel clock t."""
    L, F = config.clocks_per_readout, config.clocks_per_tick
    return (t % L) // F + 1, int(t % L == L - 1)


@pytest.mark.parametrize("config", EDGE_CONFIGS, ids=str)
def test_timing_follows_spec_clocks(config):
    L = config.clocks_per_readout
    clocks = 3 * L + 2 if L > 1 else 6
    seen = run_timing(config, clocks)
    for t, (ccc, last, valid) in enumerate(seen):
        c, s_r = expected(config, t - 1)
        assert last == s_r, t
        if config.is_te:
            assert ccc == c, t
        # frame_valid seen by edge t is the S_r strobe of clock t - 1 (latency 1)
        assert valid == (expected(config, t - 1)[1] if t > 0 else 0), t
    assert sum(last for _, last, _ in seen) == (clocks - 1) // L + 1


def test_timing_restarts_after_synchronous_reset():
    config = SensorConfig(b1=2, b2=2, clocks_per_tick=3)      # F = 3, alpha = 3, L = 9
    r = 13                                                    # mid-interval, not on a tick
    seen = run_timing(config, 40, reset_at=r)
    for t in range(r + 1, 40):
        ccc, last, _ = seen[t]
        assert (ccc, last) == expected(config, t - r - 2), t
    assert seen[r + 1][2] == 0                                # frame_valid cleared by the reset
    assert seen[r][0] != 1                                    # (the count was really mid-way)


def test_timing_ports():
    assert "ccc" in ReadoutTiming(SensorConfig()).signature.members
    assert "ccc" not in ReadoutTiming(SensorConfig(mode="ml")).signature.members
    with pytest.raises(ConfigError, match="SensorConfig"):
        ReadoutTiming("te")
