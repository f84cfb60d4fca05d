"""Poisson sampler by table inversion, for the fast simulator (:mod:`tespike.golden.fastsim`).

Why hand-written: ``numpy.random.Generator.poisson`` spends 30-70 ns per draw
(transformed rejection, a few logs per draw), and the simulator draws millions
of per-clock electrons whose mean is constant over a pixel's L clocks. numpy
has no table sampler; a table of the integer part of the mean is built once
and then costs a few array passes per draw.

Law (exact decomposition): ``Poisson(lam) = Poisson(g) + Poisson(r)``, independent,
``g = floor(lam)``, ``r = lam - g`` in [0, 1).

* ``Poisson(g)`` by inversion of a 53-bit uniform integer ``V`` against the
  table's CDF, held as integers scaled to ``2^53`` (the draw is
  ``lo + #{k : C[k] <= V}``), found through a guide table (Chen and Asau): the
  top bits of ``V`` pick a bucket; a bucket lying inside one CDF step gives the
  draw at once, the few others are settled by bisection between the first
  candidates of the bucket and of the next one. The table covers ``[lo, hi]``,
  chosen with the rigorous tail bounds of :mod:`tespike.golden.light` so that the
  mass left out on each side is below ``exp(log_tail)``: a draw outside is one
  of the simulator's bounded "surely not" events (docs/simulator.md, scene
  budget). The pmf comes from products of the ratios ``g / k`` around the mode,
  normalised by their exactly rounded sum (``math.fsum``): relative error a few
  ``1e-16`` where the pmf is large, whereas ``-g + k log g - lgamma(k + 1)``
  would lose ``g log g x 1e-16`` (``1e-12`` at g = 1000) to cancellation. The
  integer pmf is rounded to sum to exactly ``2^53`` (largest remainders), so
  each entry is within one unit (``2^-53``) of the float pmf.
* ``Poisson(r)``, one draw per element: inversion of a float64 uniform ``u``
  (``rng.random``, a multiple of ``2^-53``): the count of thresholds
  ``F_k = P(X <= k) <= u``, the first two as passes over all draws, then
  carried over the shrinking set of draws still above the running CDF (a
  fraction ``r^2 / 2`` or less), up to a cap whose tail is again below
  ``exp(log_tail)``. With ``clocks``, by splitting instead: L iid Poisson(r)
  counts are, exactly, a ``Poisson(L r)`` total whose events fall in
  independent uniform clocks, which costs per event (``r < 1`` per draw)
  rather than per draw.

Precision: each table entry is within ``2^-53`` of the Poisson pmf (measured
0.66 units at most), each fraction threshold within a few units, like any
float64 sampler (numpy's included); the ``exp(log_tail)`` truncation is far
smaller than that. The lookups run in blocks of ``CHUNK`` draws so that their
arrays stay in cache, and a call whose tables do not fit in cache together
(many distinct means) draws its columns sorted by mean. Speed against numpy:
``benchmarks/bench_poisson.py``.

Means above ``max_tabled`` go to ``rng.poisson`` (a table there would be large
and rarely reused), and so do the least used means of a call whose tables
would not fit ``max_cache_bytes`` together (rebuilding tables every call would
cost far more than it saves). Output is deterministic for a given generator state and
input, whatever the cache holds.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .errors import InputError
from .light import POISSON_LAM_MAX, log_poisson_tail_above, log_poisson_tail_below

#: CDF scale: table entries are integers out of 2^53.
ONE = 1 << 53

#: Guide buckets per standard deviation of the table (rounded up to a power of
#: 2): about 4 % of draws land in a bucket holding a CDF step (settled apart).
GUIDE_PER_SD = 128

#: Draws per block of the table lookup: its arrays (512 KiB each) stay in cache.
CHUNK = 1 << 16

#: Guide bytes of the tables of one call above which columns are drawn sorted by mean.
LOCAL_BYTES = 1 << 20

#: Means whose table ranges (:func:`support`) are found together, in aligned blocks.
SUPPORT_BLOCK = 256

#: Bit generators whose ``random_raw`` yields 64 random bits (MT19937 gives 32).
_RAW64 = ("PCG64", "PCG64DXSM", "Philox", "SFC64")


# -- one table --------------------------------------------------------------------

def support(g: np.ndarray, log_tail: float) -> tuple[np.ndarray, np.ndarray]:
    """Table range ``[lo, hi]`` per integer mean g (arrays): the largest lo with
    ``P(X < lo)`` and the smallest hi with ``P(X > hi)`` bounded below
    ``exp(log_tail)``, by bisection on the rigorous bounds."""
    g = np.asarray(g, np.int64)
    # lo: bound(lo - 1) < log_tail holds at lo = 0, fails at lo = g + 1 (no information)
    a, b = np.zeros_like(g), g + 1           # ok(a), not ok(b) (or b = a + 1 when g = 0)
    while np.any(b - a > 1):
        mid = (a + b) // 2
        ok = log_poisson_tail_below(g, mid - 1) < log_tail
        a, b = np.where(ok, mid, a), np.where(ok, b, mid)
    lo = np.where(g > 0, a, 0)
    # hi: bound(hi + 1) < log_tail fails at hi = g - 1, holds far enough up
    span = np.ceil(4.0 * np.sqrt(-log_tail * (g + 1.0)) - 2.0 * log_tail).astype(np.int64) + 2
    top = g + span
    while True:
        bad = ~(log_poisson_tail_above(g, top + 1) < log_tail) & (g > 0)
        if not bad.any():
            break
        top = np.where(bad, g + 2 * (top - g), top)
    a, b = g - 1, top                        # not ok(a), ok(b)
    while np.any(b - a > 1):
        mid = (a + b) // 2
        ok = log_poisson_tail_above(g, mid + 1) < log_tail
        a, b = np.where(ok, a, mid), np.where(ok, mid, b)
    hi = np.where(g > 0, b, 0)
    return lo, hi


def table_pmf(g: int, lo: int, hi: int) -> np.ndarray:
    """Poisson(g) pmf on ``[lo, hi]`` (float64, normalised on the range), from the
    ratios ``p(k + 1) / p(k) = g / (k + 1)`` outward from the mode g."""
    if g == 0:
        return np.ones(1)
    up = np.cumprod(g / np.arange(g + 1, hi + 1, dtype=np.float64))
    down = np.cumprod(np.arange(g, lo, -1, dtype=np.float64) / g)[::-1]
    w = np.concatenate([down, [1.0], up])
    return w / math.fsum(w.tolist())


def integer_pmf(p: np.ndarray) -> np.ndarray:
    """``p * 2^53`` rounded to int64 summing to exactly ``2^53`` (largest
    remainders: each entry within one unit of ``p * 2^53``)."""
    x = p * float(ONE)
    q = np.floor(x).astype(np.int64)
    frac = x - q
    d = ONE - int(q.sum())
    if d > 0:
        q += d // q.size
        q[np.argsort(-frac, kind="stable")[:d % q.size]] += 1
    elif d < 0:
        order = np.argsort(frac, kind="stable")
        order = order[q[order] > 0][:-d]
        q[order] -= 1
    return q


def guide_bits(g: np.ndarray) -> np.ndarray:
    """Guide size ``2^bits`` per mean g: ``GUIDE_PER_SD`` buckets per standard
    deviation, at least 2, a power of 2."""
    sd = np.sqrt(np.maximum(np.asarray(g, np.float64), 1.0))
    return np.maximum(1, np.ceil(np.log2(GUIDE_PER_SD * sd))).astype(np.int64)


def build_table(g: int, log_tail: float, lo: int | None = None, hi: int | None = None) -> dict:
    """The table of Poisson(g): ``lo``, ``cdf`` (int64, last entry ``2^53``),
    ``bits``, ``value`` (int64 per bucket: the draw, or -1 when a CDF step falls
    inside the bucket; one more -1 at the end) and ``first`` (per bucket and one
    sentinel: the first index k with ``cdf[k]`` above the bucket's start, at most
    ``len(cdf) - 1``). ``lo, hi``: the :func:`support` when already known."""
    if lo is None or hi is None:
        lo, hi = (int(v[0]) for v in support(np.array([g]), log_tail))
    cdf = np.cumsum(integer_pmf(table_pmf(g, lo, hi)))
    bits = int(guide_bits(g))
    width = 1 << (53 - bits)
    starts = np.arange((1 << bits) + 1, dtype=np.int64) * width
    first = np.minimum(np.searchsorted(cdf, starts, side="right"), cdf.size - 1)
    last = np.searchsorted(cdf, starts[1:] - 1, side="right")
    value = np.where(first[:-1] == last, lo + first[:-1], -1)
    return {"lo": lo, "cdf": cdf, "bits": bits,
            "value": np.append(value, -1).astype(np.int64), "first": first.astype(np.int32)}


def table_bytes(g: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Cache bytes of the tables of means g on ``[lo, hi]`` (guide: 12 bytes per
    bucket, CDF and draw values: 16 bytes per entry)."""
    return 12 * ((1 << guide_bits(g)) + 1) + 16 * (hi - lo + 1)


# -- the fractional part ---------------------------------------------------------

def fraction_kmax(r_max: float, log_tail: float) -> int:
    """Largest count the ``Poisson(r)`` inversion returns: ``P(X > kmax)`` is
    below ``exp(log_tail)`` for every ``r <= r_max`` (Chernoff bound)."""
    k = 1
    while not log_poisson_tail_above(r_max, k + 1) < log_tail:
        k += 1
    return k


def fraction_cdf(r: np.ndarray, kmax: int) -> np.ndarray:
    """Thresholds ``F_k = P(X <= k)``, X ~ Poisson(r), for k = 0..kmax - 1:
    ``(kmax, n)`` float64; a uniform u gives ``#{k : F_k <= u}``."""
    r = np.asarray(r, np.float64)
    f = np.empty((kmax,) + r.shape)
    p = np.exp(-r)
    f[0] = p
    for k in range(1, kmax):
        p = p * r / k
        f[k] = f[k - 1] + p
    return f


# -- the sampler -------------------------------------------------------------------

class PoissonSampler:
    """Poisson draws with per-column means, by tables of the integer part.

    ``log_tail``: natural log of the mass each table may leave out on each side
    (the simulator's per-clock budget). ``max_tabled``: means above it go to
    ``rng.poisson``. ``max_cache_bytes``: the tables kept between calls; when a
    call needs more, the means with the most columns are tabled and the others
    go to ``rng.poisson`` (a choice made from lam alone, so the output never
    depends on what was cached before).
    Work buffers for one block of draws (about ``CHUNK`` draws, or a row of a
    call with more columns) are kept for reuse: fresh pages cost about as much
    as a pass. :meth:`clear` drops them with the tables.
    """

    def __init__(self, log_tail: float, max_tabled: int = 4096, max_cache_bytes: int = 64 << 20):
        if not (isinstance(log_tail, (int, float)) and math.isfinite(log_tail) and log_tail < 0):
            raise InputError(f"log_tail must be finite and negative (got {log_tail!r})")
        if not (isinstance(max_tabled, (int, np.integer)) and 0 <= max_tabled <= 1 << 20):
            raise InputError(f"max_tabled must be an integer in 0..2^20 (got {max_tabled!r})")
        if not (isinstance(max_cache_bytes, (int, np.integer)) and 0 < max_cache_bytes <= 1 << 34):
            raise InputError(f"max_cache_bytes must be an integer in 1..2^34 (got {max_cache_bytes!r})")
        self.log_tail = float(log_tail)
        self.max_tabled = int(max_tabled)
        self.max_cache_bytes = int(max_cache_bytes)
        self.kmax = fraction_kmax(1.0, self.log_tail)
        size = self.max_tabled + 1
        self._lo = np.full(size, -1, np.int64)       # table range, -1 until known
        self._hi = np.zeros(size, np.int64)
        self._nbytes = np.zeros(size, np.int64)
        self.clear()
        biggest = int(self._sizes(np.array([self.max_tabled]))[0])
        if self.max_cache_bytes < biggest:
            raise InputError(f"max_cache_bytes {max_cache_bytes} cannot hold the table of mean "
                             f"{max_tabled} ({biggest} bytes)")

    def clear(self) -> None:
        """Drop every cached table and the work buffers."""
        size = self.max_tabled + 1
        self._built = np.zeros(size, bool)
        self._gbase = np.zeros(size, np.int64)     # start of the table's guide
        self._shift = np.zeros(size, np.uint64)    # 64 - guide bits
        self._coff = np.zeros(size, np.int64)      # start of the table's CDF
        self._clen = np.zeros(size, np.int64)      # entries of the table's CDF
        self._value = np.zeros(0, np.int64)
        self._first = np.zeros(0, np.int32)       # per bucket: first candidate, index into _cdf
        self._kval = np.zeros(0, np.int64)         # per CDF entry: the draw it stands for
        self._cdf = np.zeros(0, np.int64)
        self._banks = {}                           # the buffers the four banks above are views of
        self._work = np.zeros(0, np.int64)
        self._mask = np.zeros(0, bool)
        self.build_seconds = 0.0

    @property
    def cache_bytes(self) -> int:
        """Bytes held by the cached tables."""
        return self._value.nbytes + self._first.nbytes + self._cdf.nbytes + self._kval.nbytes

    def table(self, g: int) -> dict:
        """The cached table of Poisson(g) (built if missing): lo, cdf, bits, value, first."""
        if not 0 <= g <= self.max_tabled:
            raise InputError(f"mean {g} is not tabled (0..{self.max_tabled})")
        self._ensure(np.array([g]))
        gb, co, n = int(self._gbase[g]), int(self._coff[g]), int(self._clen[g])
        bits = 64 - int(self._shift[g])
        value = self._value[gb:gb + (1 << bits) + 1]
        return {"lo": int(self._lo[g]), "cdf": self._cdf[co:co + n], "bits": bits,
                "value": np.maximum(value, -1), "first": self._first[gb:gb + (1 << bits) + 1] - co}

    def _sizes(self, gs: np.ndarray) -> np.ndarray:
        """Table bytes of the means gs (supports computed once per mean, for whole
        blocks of SUPPORT_BLOCK means at a time: a bisection costs about as much for
        one mean as for hundreds, and a scene's means come a few new ones per call)."""
        new = gs[self._lo[gs] < 0]
        if new.size:
            blocks = np.sort(new // SUPPORT_BLOCK)           # (np.unique would import numpy.ma)
            blocks = blocks[np.concatenate(([True], blocks[1:] != blocks[:-1]))] * SUPPORT_BLOCK
            new = (blocks[:, None] + np.arange(SUPPORT_BLOCK)).reshape(-1)
            new = new[(new <= self.max_tabled) & (self._lo[np.minimum(new, self.max_tabled)] < 0)]
            lo, hi = support(new, self.log_tail)
            self._lo[new], self._hi[new] = lo, hi
            self._nbytes[new] = table_bytes(new, lo, hi)
        return self._nbytes[gs]

    def _ensure(self, gs: np.ndarray) -> None:
        """Build the missing tables of the means gs (which fit the cache together)."""
        missing = gs[~self._built[gs]]
        if not missing.size:
            return
        t0 = time.perf_counter()
        need = int(self._sizes(missing).sum())
        if self.cache_bytes + need > self.max_cache_bytes:
            work, mask, spent = self._work, self._mask, self.build_seconds
            self.clear()
            self._work, self._mask, self.build_seconds = work, mask, spent
            missing = gs
        value, first, cdf, kval = [], [], [], []
        gbase, coff = self._value.size, self._cdf.size
        for g in missing.tolist():
            t = build_table(g, self.log_tail, int(self._lo[g]), int(self._hi[g]))
            self._built[g] = True
            self._gbase[g], self._coff[g], self._clen[g] = gbase, coff, t["cdf"].size
            self._shift[g] = 64 - t["bits"]
            f = t["first"].astype(np.int64) + coff
            # a bucket holding a CDF step says where its search starts: -1 - (index into _cdf)
            value.append(np.where(t["value"] < 0, -1 - f, t["value"]))
            first.append(f.astype(np.int32))
            cdf.append(t["cdf"])
            kval.append(np.arange(t["lo"], t["lo"] + t["cdf"].size, dtype=np.int64))
            gbase += t["value"].size
            coff += t["cdf"].size
        for name, parts in (("_value", value), ("_first", first), ("_cdf", cdf), ("_kval", kval)):
            setattr(self, name, self._append(name, parts))
        self.build_seconds += time.perf_counter() - t0

    def _append(self, name: str, parts: list[np.ndarray]) -> np.ndarray:
        """The bank ``name`` (``_value``, ``_first``, ``_cdf`` or ``_kval``) with ``parts``
        appended: a view of the filled start of a buffer whose capacity doubles when it
        fills (up to ``max_cache_bytes``), so that tables built a few per call are
        copied about twice each on average, not with the whole bank on every call
        (that cost more than the builds on scenes with many distinct means)."""
        bank = getattr(self, name)
        used, add = bank.size, sum(p.size for p in parts)
        buffer = self._banks.get(name)
        if buffer is None or used + add > buffer.size:
            cap = max(used + add, self.max_cache_bytes // bank.itemsize)   # no bank outgrows the cache
            grown = np.empty(min(max(2 * (used + add), 1024), cap), bank.dtype)
            grown[:used] = bank
            buffer = self._banks[name] = grown
        end = used
        for p in parts:
            buffer[end:end + p.size] = p
            end += p.size
        return buffer[:end]

    def draw(self, rng: np.random.Generator, lam, clocks: int | None = None) -> np.ndarray:
        """Independent Poisson draws (int64): ``(clocks, n)`` with column j of mean
        ``lam[j]`` when ``clocks`` is given (lam 1-D), else one per element of lam."""
        lam = np.asarray(lam, np.float64)
        if lam.size and not (lam.min() >= 0 and lam.max() <= POISSON_LAM_MAX):   # NaN fails both
            raise InputError(f"Poisson means must be finite, >= 0 and <= {POISSON_LAM_MAX:.6g} "
                             f"(numpy's limit); got {lam.min()!r}..{lam.max()!r}")
        if clocks is None:
            return self._draw(rng, lam.reshape(-1), 1).reshape(lam.shape)
        if lam.ndim != 1:
            raise InputError(f"with clocks, lam must be 1-D (got shape {lam.shape})")
        if not (isinstance(clocks, (int, np.integer)) and clocks >= 0):
            raise InputError(f"clocks must be an integer >= 0 (got {clocks!r})")
        return self._draw(rng, lam, int(clocks))

    def _draw(self, rng, lam: np.ndarray, L: int) -> np.ndarray:
        tab = self._tabled(lam)
        if tab.all():
            return self._draw_tabled(rng, lam, lam.astype(np.int64), L)
        out = np.empty((L, lam.size), np.int64)
        cols = np.flatnonzero(tab)
        if cols.size:
            out[:, cols] = self._draw_tabled(rng, lam[cols], lam[cols].astype(np.int64), L)
        big = np.flatnonzero(~tab)
        out[:, big] = rng.poisson(lam[big][None, :], size=(L, big.size))
        return out

    def _tabled(self, lam: np.ndarray) -> np.ndarray:
        """Which columns use tables (their tables then cached): means up to
        ``max_tabled``, and when their tables do not fit ``max_cache_bytes``
        together, those of the means with the most columns that do (ties to the
        smaller mean); the rest go to ``rng.poisson``, never a rebuild per call."""
        tab = lam <= self.max_tabled
        g = lam[tab].astype(np.int64)
        counts = np.bincount(g, minlength=1)
        gs = np.flatnonzero(counts)
        sizes = self._sizes(gs)
        if sizes.sum() > self.max_cache_bytes:
            order = np.argsort(-counts[gs], kind="stable")
            keep = gs[order[np.cumsum(sizes[order]) <= self.max_cache_bytes]]
            tabled = np.zeros(self.max_tabled + 1, bool)
            tabled[keep] = True
            tab[tab] = tabled[g]
            gs = np.sort(keep)
        self._ensure(gs)
        return tab

    def _buffers(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        if self._work.size < size:
            self._work, self._mask = np.empty(size, np.int64), np.empty(size, bool)
        return self._work[:size], self._mask[:size]

    def _draw_tabled(self, rng, lam: np.ndarray, g: np.ndarray, L: int) -> np.ndarray:
        """``Poisson(g) + Poisson(r)`` for columns whose tables are cached. When the
        tables in use are too large to stay in cache together (``LOCAL_BYTES``) and
        there are several clocks, the columns are drawn sorted by mean, in blocks of
        columns sharing few tables, and put back in place at the end (a gather pass
        costs less than a cache miss per draw)."""
        n = lam.size
        if L > 1 and n > 1:
            gs = np.flatnonzero(np.bincount(g))
            if gs.size > 1 and int((12 << guide_bits(gs)).sum()) > LOCAL_BYTES:
                perm = np.argsort(g, kind="stable")
                res = self._draw_tabled_in_order(rng, lam[perm], g[perm], L, by_columns=True)
                inv = np.empty_like(perm)
                inv[perm] = np.arange(n)
                return np.take(res, inv, axis=1, out=np.empty_like(res), mode="clip")
        return self._draw_tabled_in_order(rng, lam, g, L)

    def _draw_tabled_in_order(self, rng, lam, g, L, by_columns: bool = False) -> np.ndarray:
        n = lam.size
        out = self._draw_integer(rng, g, L, n, by_columns) if g.any() else np.zeros((L, n), np.int64)
        r = lam - g
        if r.any():
            (self._add_fraction if L == 1 else self._add_fraction_split)(rng, r, out)
        return out

    def _uniform64(self, rng, size: int) -> np.ndarray:
        if type(rng.bit_generator).__name__ in _RAW64:
            return rng.bit_generator.random_raw(size)
        return rng.integers(0, np.iinfo(np.uint64).max, size=size, dtype=np.uint64, endpoint=True)

    def _draw_integer(self, rng, g: np.ndarray, L: int, n: int, by_columns: bool = False) -> np.ndarray:
        """Poisson(g) per column from one 64-bit word per draw, looked up in blocks
        of about ``CHUNK`` draws so that the passes run in cache: rows (all columns),
        or with ``by_columns`` blocks of columns (all rows), or columns when L = 1;
        within a block the words are drawn row by row. The few draws whose bucket
        holds a CDF step are settled together at the end."""
        out = np.empty((L, n), np.int64)
        if not out.size:
            return out
        flat, pending = out.reshape(-1), []
        if L > 1 and by_columns:
            cols = max(1, CHUNK // L)
            block = np.empty((L, cols), np.int64)
            for c0 in range(0, n, cols):
                c1 = min(n, c0 + cols)
                part = block[:, :c1 - c0] if c1 - c0 == cols else np.empty((L, c1 - c0), np.int64)
                slow, a, x, b = self._lookup(g[c0:c1], self._uniform64(rng, L * (c1 - c0)).reshape(L, -1),
                                             part)
                out[:, c0:c1] = part
                pending.append((slow // (c1 - c0) * n + slow % (c1 - c0) + c0, a, x, b))
        elif L > 1:
            rows = max(1, CHUNK // n)
            for r0 in range(0, L, rows):
                r1 = min(L, r0 + rows)
                u = self._uniform64(rng, (r1 - r0) * n).reshape(r1 - r0, n)
                slow, a, x, b = self._lookup(g, u, out[r0:r1])
                pending.append((slow + r0 * n, a, x, b))
        else:
            for c0 in range(0, n, CHUNK):
                c1 = min(n, c0 + CHUNK)
                slow, a, x, b = self._lookup(g[c0:c1], self._uniform64(rng, c1 - c0).reshape(1, -1),
                                             out[:, c0:c1])
                pending.append((slow + c0, a, x, b))
        slow, a, x, b = (np.concatenate(p) for p in zip(*pending))
        flat[slow] = self._settle(a, x, b)
        return out

    def invert(self, g: np.ndarray, u: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``lo + #{k : cdf[k] <= u >> 11}`` for 64-bit words u ``(L, n)`` (uint64),
        column j against the table of mean ``g[j]`` (built if missing; means up to
        ``max_tabled`` whose tables fit the cache). ``out``: a C-contiguous int64
        ``(L, n)`` array to fill."""
        if not self._built[g].all():
            self._ensure(np.flatnonzero(np.bincount(g)))
        if out is None:
            out = np.empty(u.shape, np.int64)
        slow, a, x, b = self._lookup(g, u, out)
        out.reshape(-1)[slow] = self._settle(a, x, b)
        return out

    def _lookup(self, g: np.ndarray, u: np.ndarray, out: np.ndarray):
        """Guide-table pass: fills out ``(L, n)`` where the bucket of ``u >> 11``
        lies inside one CDF step; returns the other draws (flat indices into out)
        with their search range ``[a, b]`` (indices into the CDF bank) and value."""
        L, n = u.shape
        work, _ = self._buffers(L * n)
        bucket = work.reshape(L, n)
        np.right_shift(u, self._shift[g], out=bucket.view(np.uint64))
        bucket += self._gbase[g]
        self._value.take(bucket, out=out, mode="clip")   # clip: unbuffered; indices are in range
        slow = np.flatnonzero(out < 0)
        a = -1 - out.reshape(-1)[slow]         # a bucket's first candidate, coded in its value
        b = self._first[work[slow] + 1].astype(np.int64)
        x = (u.reshape(-1)[slow] >> np.uint64(11)).view(np.int64)
        return slow, a, x, b

    def _settle(self, a: np.ndarray, x: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The draw for value x with candidates ``[a, b]`` (``cdf[b] > x``): the smallest
        k there with ``cdf[k] > x``; one step settles most, bisection the rest."""
        a = a + (self._cdf[a] <= x)
        open_ = np.flatnonzero(a < b)
        while open_.size:
            lo, hi, xo = a[open_], b[open_], x[open_]
            mid = (lo + hi) >> 1
            below = self._cdf[mid] <= xo
            a[open_] = np.where(below, mid + 1, lo)
            b[open_] = np.where(below, hi, mid)
            open_ = open_[a[open_] < b[open_]]
        return self._kval[a]

    def _add_fraction(self, rng, r: np.ndarray, out: np.ndarray) -> None:
        """Add Poisson(r) to out ``(1, n)`` by inversion of one uniform per draw
        against the thresholds of :func:`fraction_cdf`: the first two as passes
        over blocks of ``CHUNK`` draws (``rng.random`` in the same order as one
        call), the next ones carried per draw still above them."""
        n = r.size
        flat = out.reshape(-1)
        work, mask = self._buffers(3 * min(n, CHUNK))
        buf = work.view(np.float64)
        tails = []
        for c0 in range(0, n, CHUNK):
            c1 = min(n, c0 + CHUNK)
            k = c1 - c0
            u, p, f = buf[:k], buf[k:2 * k], buf[2 * k:3 * k]
            rng.random(out=u)
            rc = r[c0:c1]
            np.negative(rc, out=p)
            np.exp(p, out=p)                                   # F_0 = P(0)
            np.greater_equal(u, p, out=mask[:k])
            np.add(flat[c0:c1], mask[:k].view(np.uint8), out=flat[c0:c1], casting="unsafe")
            np.multiply(p, rc, out=f)
            np.add(f, p, out=f)                                # F_1 = p + p r, as fraction_cdf
            idx = np.flatnonzero(u >= f)
            if idx.size:
                pi = p[idx]
                tails.append((idx + c0, pi * rc[idx], f[idx], u[idx]))
        if not tails:
            return
        idx, p, f, uu = (np.concatenate(t) for t in zip(*tails))
        flat[idx] += 1
        rr = r[idx]
        for k in range(2, self.kmax):
            p = p * rr / k
            f = f + p
            keep = uu >= f
            idx = idx[keep]
            if not idx.size:
                return
            flat[idx] += 1
            rr, p, f, uu = rr[keep], p[keep], f[keep], uu[keep]

    @staticmethod
    def _add_fraction_split(rng, r: np.ndarray, out: np.ndarray) -> None:
        """Add Poisson(r) per column to every clock of out ``(L, n)`` by splitting:
        L iid Poisson(r) counts are a Poisson(L r) total spread uniformly over the
        L clocks (each event in a uniform clock, independently), exactly; the cost
        is per event (r < 1 per draw), not per draw."""
        L, n = out.shape
        total = rng.poisson(L * r)
        events = int(total.sum())
        if not events:
            return
        index = np.int32 if L * n < 1 << 31 else np.int64   # int32 indices: a third faster
        pos = rng.integers(0, L, size=events, dtype=index)
        pos *= n
        pos += np.repeat(np.arange(n, dtype=index), total)
        np.add.at(out.reshape(-1), pos, 1)
