"""An outsider's check of `tespike verilog --lanes N` (SPEC sections 3, 4 and 6 only).

Written from SPEC's text alone, as the issue 19 acceptance check describes: it imports nothing
from the project (the golden model, golden.beats and the project's Icarus harness are not
used), gives every config key explicitly, writes its own Icarus testbench from the ports SPEC
section 6 names, drives random stimulus and compares every beat (content, out_first, beats per
interval, no beat before its interval ends, last beat within 2L). Used by
tests/test_stream_outsider.py; ``python3 tests/stream_outsider.py`` runs every case; environment ``RST=n`` holds reset for n
edges (default 3, 0 for none), ``MUTATE='old=>new'`` edits the generated Verilog first (to see
the check fail, e.g. ``MUTATE='q >= =>q > '``).
"""
import json, os, random, subprocess, sys, tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def word_bits(c):
    if c["mode"] == "te":
        return max(c["b1"], c["b2"]) + 1
    if c["ml_readout"] == "count":
        return c["ml_bits"]
    return c["ml_bits"].bit_length()


def reference(c, stim, H, W):
    """SPEC section 3 literally: stim[t][p] -> words[k][p]."""
    P = H * W
    F, alpha = c["clocks_per_tick"], c["alpha"]
    L = F * alpha
    theta, A = c["threshold"], c["acc_bits"]
    words = []
    acc = [0] * P; sfc = [0] * P; ovf = [0] * P; mm = [0] * P
    for t, e in enumerate(stim):
        j = (t % L) // F
        cc = j + 1
        row = []
        for p in range(P):
            q = acc[p] + e[p]
            s = 1 if q >= theta else 0
            acc[p] = min(q - theta * s, 2 ** A - 1)
            if c["mode"] == "te":
                if ovf[p] == 0 and s == 1:
                    sfc[p] += 1
                    if sfc[p] == 2 ** c["b1"]:
                        ovf[p] = 1; mm[p] = cc
            else:
                sfc[p] = min(sfc[p] + s, 2 ** c["ml_bits"] - 1)
            if t % L == L - 1:
                if c["mode"] == "te":
                    d = max(c["b1"], c["b2"])
                    w = (1 << d) | mm[p] if ovf[p] else sfc[p]
                    sfc[p] = ovf[p] = mm[p] = 0
                elif c["ml_readout"] == "count":
                    w = sfc[p]; sfc[p] = 0
                else:
                    w = sfc[p].bit_length()
                    if w > 0:
                        sfc[p] -= 2 ** (w - 1)
                row.append(w)
        if t % L == L - 1:
            words.append(row)
    return words


TB = """
`timescale 1ns/1ps
module tb;
  reg clk = 0; reg rst = 1;
  reg [{PE}-1:0] charge = 0;
  reg [{PE}-1:0] stim [0:{T}-1];
  wire out_valid, out_first;
  wire [{NW}-1:0] out_words;
  {TOP} dut (.clk(clk), .rst(rst), .charge(charge), .out_valid(out_valid), .out_first(out_first), .out_words(out_words));
  integer t, f;
  initial begin
    $readmemh("stim.hex", stim);
    f = $fopen("beats.txt", "w");
    // reset for 3 edges; inputs change on falling edges
    repeat ({RST}) begin #5 clk = 1; #5 clk = 0; end
    rst = 0;
    for (t = 0; t < {TT}; t = t + 1) begin
      charge = (t < {T}) ? stim[t] : {{{PE}{{1'b0}}}};
      #4;  // settled before edge t: outputs sampled at edge t
      if (out_valid) $fwrite(f, "%0d %0d %h\\n", t, out_first, out_words);
      if (^{{out_valid, out_first, out_words}} === 1'bx) begin $fwrite(f, "X %0d\\n", t); end
      #1 clk = 1; #5 clk = 0;
    end
    $fclose(f); $finish;
  end
endmodule
"""


def check(c, H, W, N, K, seed, log, work=None):
    rnd = random.Random(seed)
    P, E = H * W, c["input_bits"]
    L = c["clocks_per_tick"] * c["alpha"]
    wd = word_bits(c)
    T = K * L
    emax = 2 ** E - 1
    theta = c["threshold"]
    # stimulus: per-pixel, per-interval regime
    stim = [[0] * P for _ in range(T)]
    for p in range(P):
        for k in range(K):
            kind = rnd.randrange(6)
            for t in range(k * L, (k + 1) * L):
                if kind == 0: v = 0
                elif kind == 1: v = emax
                elif kind == 2: v = rnd.randint(0, emax)
                elif kind == 3: v = min(emax, rnd.randint(0, 2 * theta))
                elif kind == 4: v = min(emax, rnd.choice([0, 0, 0, theta - 1, theta, theta + 1]))
                else: v = min(emax, rnd.randint(0, max(1, theta // max(1, L // 8))))
                stim[t][p] = v
    ref = reference(c, stim, H, W)
    d = tempfile.mkdtemp(dir=work, prefix="outsider-")
    cfgp = os.path.join(d, "c.json"); json.dump(c, open(cfgp, "w"))
    v = os.path.join(d, "x.v")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-m", "tespike", "verilog", "--config", cfgp, "--height", str(H), "--width", str(W),
                        "--lanes", str(N), "--out", v], capture_output=True, text=True, env=env)
    if os.environ.get("MUTATE"):
        a, b = os.environ["MUTATE"].split("=>")
        src = open(v).read(); assert a in src, a; open(v, "w").write(src.replace(a, b, 1))
    if r.returncode != 0:
        return f"generate failed: {r.stderr.strip()}"
    top = "te_pixel_array_stream" if c["mode"] == "te" else "ml_pixel_array_stream"
    with open(os.path.join(d, "stim.hex"), "w") as fh:
        for row in stim:
            val = 0
            for p, e in enumerate(row):
                val |= e << (p * E)
            fh.write(f"{val:x}\n")
    TT = T + 2 * L + 3
    open(os.path.join(d, "tb.v"), "w").write(TB.format(RST=int(os.environ.get("RST", "3")), PE=P * E, T=T, TT=TT, NW=N * wd, TOP=top))
    r = subprocess.run(["iverilog", "-g2005", "-o", "sim", "tb.v", "x.v"], cwd=d, capture_output=True, text=True)
    if r.returncode: return "iverilog: " + r.stderr[-500:]
    r = subprocess.run(["vvp", "-n", "sim"], cwd=d, capture_output=True, text=True)
    if r.returncode: return "vvp: " + r.stderr[-500:]
    lines = open(os.path.join(d, "beats.txt")).read().split("\n")
    lines = [l for l in lines if l]
    if any(l.startswith("X") for l in lines): return "X on outputs"
    B = -(-P // N)
    beats = [(int(a), int(b), int(w, 16)) for a, b, w in (l.split() for l in lines)]
    # group
    groups = []
    for t, first, w in beats:
        if first:
            groups.append([])
        elif not groups:
            return f"beat at edge {t} before any first"
        groups[-1].append((t, w))
    if len(groups) < K: return f"only {len(groups)} intervals seen, want {K}"
    for k in range(K):
        g = groups[k]
        if len(g) != B: return f"interval {k}: {len(g)} beats, want {B}"
        end = (k + 1) * L - 1
        if g[0][0] <= end: return f"interval {k}: first beat at edge {g[0][0]}, before its last clock {end}"
        if g[-1][0] > end + 2 * L: return f"interval {k}: last beat at {g[-1][0]} > {end} + 2L"
        flat = ref[k] + [0] * (B * N - P)
        for j, (t, w) in enumerate(g):
            exp = 0
            for i in range(N):
                exp |= flat[j * N + i] << (i * wd)
            if w != exp:
                return f"interval {k} beat {j} (edge {t}): got {w:x} want {exp:x}"
    # intervals beyond K: beats must be a prefix (content not checked)
    lat = max(groups[k][-1][0] - ((k + 1) * L - 1) for k in range(K))
    log.append(f"max last-beat latency {lat} clocks (L={L})")
    return None


def full(mode, **kw):
    c = {"mode": mode, "b1": 4, "b2": 4, "alpha": 15, "clocks_per_tick": 16, "threshold": 175,
         "acc_bits": 9, "input_bits": 16, "ml_bits": 8, "ml_readout": "count"}
    c.update(kw)
    return c


CASES = [
    # (config, H, W, N, K)
    (full("te", b1=3, b2=2, alpha=3, clocks_per_tick=4, threshold=5, acc_bits=4, input_bits=3), 3, 5, 2, 5),   # L=12, 15 px: min N=2
    (full("te", b1=3, b2=2, alpha=3, clocks_per_tick=4, threshold=5, acc_bits=4, input_bits=3), 3, 5, 7, 4),   # non-divisor
    (full("te", b1=3, b2=2, alpha=3, clocks_per_tick=4, threshold=5, acc_bits=4, input_bits=3), 3, 5, 20, 4),  # N > HW
    (full("te", b1=2, b2=5, alpha=7, clocks_per_tick=1, threshold=3, acc_bits=3, input_bits=2), 2, 7, 2, 6),   # L=7, 14 px: min 2, b2>b1
    (full("te", b1=2, b2=5, alpha=7, clocks_per_tick=1, threshold=3, acc_bits=3, input_bits=2), 2, 7, 3, 6),
    (full("te", b1=1, b2=1, alpha=1, clocks_per_tick=1, threshold=1, acc_bits=1, input_bits=1), 2, 2, 4, 8),   # L=1: N must be 4
    (full("te", b1=1, b2=1, alpha=1, clocks_per_tick=3, threshold=2, acc_bits=2, input_bits=2), 2, 4, 3, 6),   # L=3, min N=3
    (full("te", b1=5, b2=3, alpha=5, clocks_per_tick=2, threshold=9, acc_bits=6, input_bits=4), 4, 3, 5, 5),   # saturating acc, b1>b2
    (full("ml", alpha=5, clocks_per_tick=3, threshold=4, acc_bits=4, input_bits=3, ml_bits=3), 3, 4, 1, 4),    # L=15, N=1
    (full("ml", alpha=5, clocks_per_tick=3, threshold=4, acc_bits=4, input_bits=3, ml_bits=3), 3, 4, 5, 4),
    (full("ml", b2=2, alpha=3, clocks_per_tick=1, threshold=1, acc_bits=2, input_bits=2, ml_bits=1), 3, 3, 3, 6),  # 1-bit ML, L=3
    (full("ml", alpha=4, clocks_per_tick=5, threshold=3, acc_bits=3, input_bits=3, ml_bits=5, ml_readout="msb"), 2, 5, 1, 8),
    (full("ml", alpha=4, clocks_per_tick=5, threshold=3, acc_bits=3, input_bits=3, ml_bits=5, ml_readout="msb"), 2, 5, 3, 8),
    (full("ml", alpha=2, clocks_per_tick=2, threshold=2, acc_bits=3, input_bits=3, ml_bits=7, ml_readout="msb"), 3, 3, 4, 8),  # L=4, min N=3
    (full("ml", alpha=2, clocks_per_tick=2, threshold=1, acc_bits=1, input_bits=1, ml_bits=2, ml_readout="msb"), 1, 6, 2, 8),  # L=4, ml_bits=2
    (full("ml", b2=2, alpha=1, clocks_per_tick=1, threshold=2, acc_bits=2, input_bits=2, ml_bits=4, ml_readout="msb"), 1, 3, 3, 10),  # L=1
    (full("te", b1=16, b2=16, alpha=3, clocks_per_tick=2, threshold=1, acc_bits=2, input_bits=5), 2, 3, 1, 3),  # wide counters
    (full("te", b1=4, b2=4, alpha=15, clocks_per_tick=16, threshold=175, acc_bits=9, input_bits=16), 4, 4, 1, 3),  # paper TE
]

if __name__ == "__main__":
    fails = 0
    for idx, (c, H, W, N, K) in enumerate(CASES):
        for seed in (1, 2):
            log = []
            err = check(c, H, W, N, K, seed * 100 + idx, log)
            tag = f"{c['mode']}{'-' + c['ml_readout'] if c['mode'] == 'ml' else ''} {H}x{W} N={N} L={c['clocks_per_tick'] * c['alpha']} seed={seed}"
            print(("FAIL " + tag + ": " + err) if err else ("ok   " + tag + " " + "; ".join(log)), flush=True)
            fails += bool(err)
    print("failures:", fails)
    sys.exit(1 if fails else 0)
