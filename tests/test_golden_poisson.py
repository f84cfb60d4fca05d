"""tespike.golden.poisson: table sampler's law, exactly (tables against 50-digit pmfs) and
statistically (against numpy's Generator.poisson), and its lookup against plain inversion."""

import math
from decimal import Decimal, localcontext

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tespike.golden.light import log_poisson_tail_above, log_poisson_tail_below
from tespike.golden.poisson import ONE, PoissonSampler, fraction_cdf, fraction_kmax, support

LOG_TAIL = -75.0


def exact_pmf(m, ks):
    """Poisson(m) pmf at the integers ks (ascending, consecutive), 50 significant
    digits, and the masses below ks[0] and above ks[-1] (summed until negligible)."""
    with localcontext() as ctx:
        ctx.prec = 50
        m = Decimal(repr(m))
        k0 = int(ks[0])
        if m == 0:
            return [Decimal(int(k == 0)) for k in ks], Decimal(0), Decimal(0)
        lnfact = sum((Decimal(j).ln() for j in range(2, k0 + 1)), Decimal(0))
        p = (-m + k0 * m.ln() - lnfact).exp()
        first = p
        out = []
        for k in range(k0, int(ks[-1]) + 1):
            out.append(p)
            p = p * m / (k + 1)
        above, k = Decimal(0), int(ks[-1]) + 1
        while p > Decimal(10) ** -45 * (above + Decimal(10) ** -300) or k <= m:
            above += p
            p = p * m / (k + 1)
            k += 1
        below, p, k = Decimal(0), first, k0
        while k > 0:
            p = p * k / m
            k -= 1
            below += p
            if p < Decimal(10) ** -45 * below and k < m:
                break
        return out, below, above


@pytest.mark.parametrize("g", [1, 2, 7, 63, 175, 328, 1000, 4096])
def test_table_pmf_exact(g):
    """Implied pmf of the integer CDF within 1.25 x 2^-53 of the true pmf; the mass
    left out on each side below exp(log_tail), by the bound and exactly."""
    sampler = PoissonSampler(LOG_TAIL)
    t = sampler.table(g)
    lo, cdf = t["lo"], t["cdf"]
    assert cdf[-1] == ONE and np.all(np.diff(cdf) >= 0) and cdf[0] >= 0
    implied = np.diff(np.concatenate([[0], cdf])) / ONE
    ks = np.arange(lo, lo + cdf.size)
    true, below, above = exact_pmf(g, ks)
    err = max(abs(Decimal(float(a)) - b) for a, b in zip(implied, true))
    assert err < Decimal(1.25 / ONE), err          # within about one unit of 2^-53 (measured: 0.66)
    hi = lo + cdf.size - 1
    assert log_poisson_tail_below(np.float64(g), lo - 1) < LOG_TAIL
    assert log_poisson_tail_above(np.float64(g), hi + 1) < LOG_TAIL
    assert below < Decimal(math.exp(LOG_TAIL)) and above < Decimal(math.exp(LOG_TAIL))
    # tight: one entry less on either side would break the bound
    assert not log_poisson_tail_above(np.float64(g), hi) < LOG_TAIL
    if lo > 0:
        assert not log_poisson_tail_below(np.float64(g), lo) < LOG_TAIL


def test_bounds_with_an_array_of_k_are_the_bounds_of_each_k():
    m = np.array([0.0, 1e-9, 0.5, 3.0, 175.0, 1000.0])
    for k in [-1, 0, 1, 2, 5, 150, 176, 300, 1200]:
        np.testing.assert_array_equal(log_poisson_tail_below(m, np.full(m.shape, k)), log_poisson_tail_below(m, k))
        np.testing.assert_array_equal(log_poisson_tail_above(m, np.full(m.shape, k)), log_poisson_tail_above(m, k))


def test_support_zero_and_monotone():
    lo, hi = support(np.array([0, 1, 2, 100, 101]), LOG_TAIL)
    assert lo[0] == hi[0] == 0 and lo[1] == 0
    assert np.all(np.diff(lo) >= 0) and np.all(np.diff(hi) >= 0)


@pytest.mark.parametrize("r", [1e-300, 1e-9, 0.3, 0.5, 0.999, 1 - 2.0 ** -52])
def test_fraction_inversion_exact(r):
    """A 53-bit uniform u gives k with probability
    (ceil(F_k 2^53) - ceil(F_{k-1} 2^53)) / 2^53: within 1e-15 of the pmf."""
    kmax = fraction_kmax(1.0, LOG_TAIL)
    f = fraction_cdf(np.array([r]), kmax)[:, 0]
    assert np.all(np.diff(f) >= 0)
    edges = np.concatenate([[0], np.ceil(f * ONE), [ONE]])
    implied = np.diff(edges) / ONE                    # k = 0..kmax (kmax: u above every F)
    true, _, above = exact_pmf(r, np.arange(0, kmax + 1))
    err = max(abs(Decimal(float(a)) - b) for a, b in zip(implied, true))
    assert err < Decimal("1e-15"), err
    assert above < Decimal(math.exp(LOG_TAIL))        # P(X > kmax)
    assert log_poisson_tail_above(np.float64(1.0), kmax + 1) < LOG_TAIL


def test_lookup_is_plain_inversion():
    """The guide table and its slow path equal searchsorted on the CDF, for words
    at every bucket edge, at every CDF step +-1 and random ones."""
    sampler = PoissonSampler(LOG_TAIL)
    rng = np.random.default_rng(5)
    for g in [0, 1, 3, 40, 175, 1000, 4096]:
        t = sampler.table(g)
        cdf, bits = t["cdf"], t["bits"]
        v = [np.arange(1 << bits, dtype=np.int64) << (53 - bits),
             (np.arange(1, (1 << bits) + 1, dtype=np.int64) << (53 - bits)) - 1,
             cdf[:-1], cdf[:-1] - 1, np.maximum(cdf[:-1] + 1, 0) % ONE,
             rng.integers(0, ONE, 20000), np.array([0, ONE - 1])]
        v = np.concatenate(v).astype(np.int64)
        v = v[(v >= 0) & (v < ONE)]                   # 53-bit words only
        low = rng.integers(0, 1 << 11, v.size).astype(np.uint64)
        u = (v.astype(np.uint64) << np.uint64(11)) | low
        got = sampler.invert(np.full(v.size, g), u[None, :])[0]
        np.testing.assert_array_equal(got, t["lo"] + np.searchsorted(cdf, v, side="right"))


def test_draw_stream_is_table_then_fraction():
    """Per element: one 64-bit word per draw against the table, then one float
    uniform against the fraction's thresholds (fraction_cdf), in that order."""
    lam = np.array([0.0, 0.25, 1.0, 7.5, 63.2, 175.4, 0.999, 328.9, 3.0, 1000.5] * 300)
    sampler = PoissonSampler(LOG_TAIL)
    got = sampler.draw(np.random.default_rng(11), lam)
    ref = np.random.default_rng(11)
    g = lam.astype(np.int64)
    raw = ref.bit_generator.random_raw(lam.size)
    want = np.empty(lam.size, np.int64)
    for j in range(lam.size):
        t = sampler.table(int(g[j]))
        want[j] = t["lo"] + np.searchsorted(t["cdf"], int(raw[j] >> np.uint64(11)), side="right")
    u = ref.random(lam.size)
    f = fraction_cdf(lam - g, sampler.kmax)
    want += (u[None, :] >= f).sum(axis=0)
    np.testing.assert_array_equal(got, want)


def tvd(a, b):
    top = int(max(a.max(), b.max())) + 1
    return 0.5 * np.abs(np.bincount(a.ravel(), minlength=top) / a.size
                        - np.bincount(b.ravel(), minlength=top) / b.size).sum()


LAMS = [0.0, 1e-9, 0.3, 0.999, 1.0, 7.5, 63.2, 175.4, 328.9, 1000.5, 5000.25]


@pytest.mark.parametrize("clocks", [None, 240])
def test_law_statistical(clocks):
    """Mean and variance within 4 standard errors of lam; histogram TVD against
    numpy's sampler at the level of two independent numpy runs."""
    sampler = PoissonSampler(LOG_TAIL, max_tabled=4096)
    rng = np.random.default_rng(2024)
    n = 200_000 if clocks is None else 240_000 // clocks
    size = (n,) if clocks is None else (clocks, n)
    floors, tvds = [], []
    for lam in LAMS:
        x = sampler.draw(rng, np.full(n, lam), clocks=clocks)
        assert x.shape == size and x.dtype == np.int64
        N = x.size
        assert abs(x.mean() - lam) <= 4 * math.sqrt(lam / N) + 1e-12, (lam, x.mean())
        assert abs(x.var() - lam) <= 4 * math.sqrt((lam + 2 * lam * lam) / N) + 1e-12, (lam, x.var())
        ref = rng.poisson(lam, size)
        tvds.append(tvd(x, ref))
        floors.append(np.mean([tvd(rng.poisson(lam, size), ref) for _ in range(4)]))
    tvds, floors = np.array(tvds), np.array(floors)
    # each within 2x the mean floor of 4 numpy runs (+ slack where both are tiny), none biased on average
    assert np.all(tvds <= 2 * floors + 2e-4), (tvds, floors)
    assert tvds.sum() <= 1.25 * floors.sum(), (tvds, floors)


def test_clock_totals_are_poisson():
    """Per column, the sum over the clocks has variance L lam (the fraction is
    spread over the clocks with a random total), and clocks are uncorrelated."""
    sampler = PoissonSampler(LOG_TAIL)
    L, n = 240, 4000
    for lam in [0.5, 3.7, 175.4]:
        x = sampler.draw(np.random.default_rng(3), np.full(n, lam), clocks=L)
        s = x.sum(axis=0)
        v = L * lam
        assert abs(s.var() - v) <= 4 * math.sqrt((v + 2 * v * v) / n), (lam, s.var(), v)
        c = np.corrcoef(x[0], x[1])[0, 1]
        assert abs(c) < 4 / math.sqrt(n)


def test_mixed_columns_and_fallback():
    """Mixed means per column, zeros, huge means (numpy fallback), grouped tables."""
    lam = np.array([0.0, 1e-300, 0.7, 88.3, 4096.9, 4097.0, 3e4, 1e7])
    rng = np.random.default_rng(8)
    x = PoissonSampler(LOG_TAIL, max_tabled=4096).draw(rng, np.repeat(lam, 50), clocks=2000)
    assert x.shape == (2000, 400)
    m = x.reshape(2000, 8, 50).mean(axis=(0, 2))
    assert np.all(np.abs(m - lam) <= 4 * np.sqrt(lam / 100_000) + 1e-12), m
    assert np.all(x[:, :100] == 0)
    # means above max_tabled only: exactly numpy's draws on the same stream
    big = np.array([5000.5, 1e6])
    got = PoissonSampler(LOG_TAIL, max_tabled=100).draw(np.random.default_rng(1), big, 7)
    np.testing.assert_array_equal(got, np.random.default_rng(1).poisson(big[None, :], size=(7, 2)))


def test_deterministic_whatever_the_cache():
    """Same generator state and means give the same draws, fresh sampler or not,
    and with a cache so small that the tables are built in groups."""
    lam = np.exp(np.random.default_rng(0).uniform(np.log(1e-3), np.log(400), 1000))
    a = PoissonSampler(LOG_TAIL).draw(np.random.default_rng(9), lam, clocks=30)
    used = PoissonSampler(LOG_TAIL)
    used.draw(np.random.default_rng(1), lam[::-1] + 0.5, clocks=3)
    used.draw(np.random.default_rng(1), np.arange(500.0))
    np.testing.assert_array_equal(used.draw(np.random.default_rng(9), lam, clocks=30), a)
    small = PoissonSampler(LOG_TAIL, max_cache_bytes=1 << 20)
    s1 = small.draw(np.random.default_rng(9), lam, clocks=30)
    assert small.cache_bytes <= 1 << 20
    small.draw(np.random.default_rng(2), lam[:5])
    np.testing.assert_array_equal(small.draw(np.random.default_rng(9), lam, clocks=30), s1)
    assert abs(s1.mean() - lam.mean()) < 4 * math.sqrt(lam.mean() / s1.size)


def test_tables_built_a_few_per_call_equal_tables_built_alone():
    """Tables appended to the banks a few calls at a time (the banks grow by doubling,
    their ranges found for blocks of means at once) are each the table built on its
    own: same range, CDF and guide, whatever was built before or after it."""
    sampler = PoissonSampler(LOG_TAIL)
    rng = np.random.default_rng(5)
    means = rng.permutation(np.arange(1, 700))[:120]
    for chunk in np.array_split(means, 40):
        sampler.draw(rng, chunk + 0.25, clocks=64)
    fresh = PoissonSampler(LOG_TAIL)
    for g in means.tolist():
        got, alone = sampler.table(g), fresh.table(g)
        fresh.clear()
        assert got["lo"] == alone["lo"] and got["bits"] == alone["bits"], g
        for key in ("cdf", "value", "first"):
            np.testing.assert_array_equal(got[key], alone[key], err_msg=f"{g} {key}")


def test_other_bit_generator():
    """A 32-bit bit generator (MT19937) goes through Generator.integers."""
    x = PoissonSampler(LOG_TAIL).draw(np.random.Generator(np.random.MT19937(4)), np.full(1000, 63.2), 100)
    assert abs(x.mean() - 63.2) <= 4 * math.sqrt(63.2 / x.size)
    assert abs(x.var() - 63.2) <= 4 * math.sqrt((63.2 + 2 * 63.2 ** 2) / x.size)


def test_shapes_and_edges():
    s = PoissonSampler(LOG_TAIL)
    rng = np.random.default_rng(1)
    assert s.draw(rng, np.zeros((3, 4))).shape == (3, 4)
    assert not s.draw(rng, np.zeros((3, 4))).any()
    assert s.draw(rng, np.float64(2.5)).shape == ()
    assert s.draw(rng, np.zeros(0), clocks=5).shape == (5, 0)
    assert s.draw(rng, np.ones(3), clocks=0).shape == (0, 3)
    assert not s.draw(rng, np.full(1000, 1e-300), clocks=100).any()


@pytest.mark.parametrize("call, match", [
    (lambda s, r: s.draw(r, np.array([1.0, -1.0])), "finite, >= 0"),
    (lambda s, r: s.draw(r, np.array([np.nan])), "finite, >= 0"),
    (lambda s, r: s.draw(r, np.array([np.inf])), "finite, >= 0"),
    (lambda s, r: s.draw(r, np.array([3.0, 1e19])), "numpy's limit"),
    (lambda s, r: s.draw(r, np.ones((2, 2)), clocks=3), "1-D"),
    (lambda s, r: s.draw(r, np.ones(2), clocks=-1), "clocks"),
    (lambda s, r: s.draw(r, np.ones(2), clocks=2.5), "clocks"),
    (lambda s, r: s.table(5000), "not tabled"),
])
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call(PoissonSampler(LOG_TAIL), np.random.default_rng(0))


@pytest.mark.parametrize("kwargs, match", [
    (dict(log_tail=0.0), "log_tail"), (dict(log_tail=float("nan")), "log_tail"),
    (dict(log_tail=-75.0, max_tabled=-1), "max_tabled"),
    (dict(log_tail=-75.0, max_cache_bytes=1000), "max_cache_bytes"),
])
def test_bad_construction(kwargs, match):
    with pytest.raises(InputError, match=match):
        PoissonSampler(**kwargs)


@pytest.mark.parametrize("local_bytes", [0, 1 << 40])
def test_sorted_columns_stream(monkeypatch, local_bytes):
    """With many tables (forced by LOCAL_BYTES = 0) columns are drawn sorted by
    mean in blocks of columns, row by row within a block; otherwise row blocks.
    Either way each draw is the plain inversion of its word, put in its column."""
    import tespike.golden.poisson as gp
    monkeypatch.setattr(gp, "LOCAL_BYTES", local_bytes)
    monkeypatch.setattr(gp, "CHUNK", 1000)              # several blocks, a ragged last one
    L, n = 37, 101
    g = np.random.default_rng(3).integers(0, 300, n)
    sampler = PoissonSampler(LOG_TAIL)
    got = sampler.draw(np.random.default_rng(21), g.astype(np.float64), clocks=L)
    raw = np.random.default_rng(21).bit_generator.random_raw(L * n)
    order = np.argsort(g, kind="stable") if local_bytes == 0 else np.arange(n)
    words = np.empty((L, n), np.uint64)
    if local_bytes == 0:
        cols, used = 1000 // L, 0
        for c0 in range(0, n, cols):
            c1 = min(n, c0 + cols)
            words[:, order[c0:c1]] = raw[used:used + L * (c1 - c0)].reshape(L, c1 - c0)
            used += L * (c1 - c0)
    else:
        words[:] = raw.reshape(L, n)
    want = np.empty((L, n), np.int64)
    for j in range(n):
        t = sampler.table(int(g[j]))
        want[:, j] = t["lo"] + np.searchsorted(t["cdf"], (words[:, j] >> np.uint64(11)).astype(np.int64),
                                               side="right")
    np.testing.assert_array_equal(got, want)


def test_sorted_columns_law():
    """Many distinct means per column (the sorted path): per-mean mean and variance."""
    lam = np.repeat(np.linspace(30.25, 3000.5, 40), 25)
    x = PoissonSampler(LOG_TAIL).draw(np.random.default_rng(6), lam, clocks=200)
    xs = x.reshape(200, 40, 25)
    N = 200 * 25
    m, v, lams = xs.mean(axis=(0, 2)), xs.var(axis=(0, 2)), lam[::25]
    assert np.all(np.abs(m - lams) <= 4 * np.sqrt(lams / N)), m - lams
    assert np.all(np.abs(v - lams) <= 4 * np.sqrt((lams + 2 * lams ** 2) / N)), v - lams


class _FixedUniforms:
    """Stands in for a Generator whose ``random(out=...)`` returns given values."""

    def __init__(self, values):
        self.values, self.used = np.asarray(values, np.float64), 0

    def random(self, out):
        out[:] = self.values[self.used:self.used + out.size]
        self.used += out.size
        return out


def test_fraction_thresholds_exactly(monkeypatch):
    """Per element, u exactly at a threshold F_k counts it, the float just below
    does not; across several blocks (CHUNK patched small)."""
    import tespike.golden.poisson as gp
    monkeypatch.setattr(gp, "CHUNK", 64)
    sampler = PoissonSampler(LOG_TAIL)
    r = np.repeat([0.3, 0.5, 0.999, 1e-9], 50)                # 1e-9: F_1 rounds to 1, u never reaches it
    f = fraction_cdf(r, sampler.kmax)
    k = np.tile(np.arange(5), 40) * (r > 1e-3)
    at = f[k, np.arange(r.size)]
    u = np.concatenate([at, np.nextafter(at, 0.0)])
    rr = np.concatenate([r, r])
    out = np.zeros((1, rr.size), np.int64)
    sampler._add_fraction(_FixedUniforms(u), rr, out)
    want = (u[None, :] >= fraction_cdf(rr, sampler.kmax)).sum(axis=0)
    np.testing.assert_array_equal(out[0], want)
    assert np.array_equal(out[0, :r.size], k + 1) and np.array_equal(out[0, r.size:], k)
    assert np.all(u < 1.0)
