# amaranth: UnusedElaboratable=no
import functools
import re
import shutil
import subprocess

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError
from tespike.golden.reference import step_reference
from tespike.rtl.verilog import array_verilog, pixel_verilog, top_verilog
from tests.configs import EDGE_CONFIGS, MSB_CONFIGS
from tests.rtl_helpers import mixed_stimulus

needs = {tool: pytest.mark.skipif(shutil.which(tool) is None, reason=f"{tool} not installed")
         for tool in ("verilator", "iverilog", "vvp")}


@functools.lru_cache(maxsize=None)
def generated(config, height, width):
    """array_verilog, shared by the tests of one config (each conversion runs Yosys, ~2 s)."""
    return array_verilog(config, height, width)


def run(cmd, cwd):
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=300)


@needs["verilator"]
@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_CONFIGS, ids=str)
def test_array_verilog_lints_clean_and_compiles(config, tmp_path):
    (tmp_path / "A.v").write_text(generated(config, 2, 3))
    lint = run(["verilator", "--lint-only", "-Wall", "A.v"], tmp_path)
    assert lint.returncode == 0 and "%Warning" not in lint.stderr, lint.stderr
    if shutil.which("iverilog"):
        build = run(["iverilog", "-g2005", "-o", "a.vvp", "A.v"], tmp_path)
        assert build.returncode == 0 and not build.stderr.strip(), build.stderr


def test_waivers_cover_only_the_generated_modules():
    """The hand-written top has no WIDTH/UNUSEDSIGNAL waiver; each waiver is switched back on."""
    text = generated(SensorConfig(), 2, 3)
    top_end = text.index("endmodule")
    assert "lint_off WIDTH" not in text[:top_end] and "lint_off UNUSED" not in text[:top_end]
    for rule in ("WIDTH", "UNUSEDSIGNAL"):
        assert text.count(f"lint_off {rule} */") == text.count(f"lint_on {rule} */") == 2


def test_top_has_spec_ports_and_instances():
    config = SensorConfig(mode="ml", ml_bits=6, input_bits=9)
    text = array_verilog(config, 3, 5)
    assert re.search(r"module ml_pixel_array \(", text)
    assert "input  wire [134:0] charge" in text          # 3*5*9 bits
    assert "output wire [89:0] frame" in text            # 3*5*6 bits
    assert text.count("module ml_pixel(") == 1 and text.count("module ml_array_timing(") == 1
    assert "H = 3;" in text and "W = 5;" in text
    assert text.count("ml_pixel pixel (") == 1                # one instance line in a generate loop


#: Flip-flop cell types after ``prep; opt`` (Yosys 0.23): a cone search stops at these.
FLOPS = "$dff,$dffe,$sdff,$sdffe,$sdffce,$adff,$adffe,$dffsr,$dffsre,$aldff,$aldffe"


def _cells_before_outputs(text: str, top: str, tmp_path) -> tuple[int, int]:
    """Yosys (``prep -flatten; opt``): (cells in the input cone of ``frame`` and ``frame_valid``
    stopped at flip-flops, i.e. logic between a register and an output; cells one step
    before the outputs, their drivers)."""
    (tmp_path / "top.v").write_text(text)
    outputs = "o:frame o:frame_valid %u"
    script = (f"read_verilog top.v; prep -flatten -top {top}; opt; "
              f"tee -o logic.txt stat {outputs} %ci*:-{FLOPS}; tee -o drivers.txt stat {outputs} %ci2")
    subprocess.run(["yosys", "-q", "-p", script], cwd=tmp_path, capture_output=True, text=True, check=True)
    counts = [int(re.search(r"Number of cells:\s+(\d+)", (tmp_path / f).read_text()).group(1))
              for f in ("logic.txt", "drivers.txt")]
    return counts[0], counts[1]


@pytest.mark.skipif(shutil.which("yosys") is None, reason="yosys not installed")
@pytest.mark.parametrize("preset", ["te", "ml", "ml-msb"])
def test_parallel_outputs_come_straight_from_flip_flops(preset, tmp_path):
    """frame is the pixels' word registers, frame_valid the timing block's register (issue 26)."""
    from tespike.golden.config import load_config
    config = load_config(preset)
    text = array_verilog(config, 2, 3)
    top = f"{config.mode}_pixel_array"
    logic, drivers = _cells_before_outputs(text, top, tmp_path)
    assert logic == 0 and drivers > 0, (logic, drivers)
    late = text.replace(".frame_valid(frame_valid));", ".frame_valid());\n  assign frame_valid = last;")
    assert late != text and _cells_before_outputs(late, top, tmp_path)[0] > 0   # last's gates are seen


def test_top_text_does_not_grow_with_the_array():
    config = SensorConfig()
    small, big = top_verilog(config, 2, 2), top_verilog(config, 128, 128)
    assert abs(len(big) - len(small)) < 40


@pytest.mark.parametrize("height, width", [(0, 4), (4, 0), (-1, 1), (1.5, 2)])
def test_array_verilog_refuses_bad_size(height, width):
    with pytest.raises(ConfigError, match="height|width"):
        array_verilog(SensorConfig(), height, width)


def test_pixel_verilog_refuses_non_config():
    with pytest.raises(ConfigError, match="SensorConfig"):
        pixel_verilog({"mode": "te"})


TESTBENCH = """\
`timescale 1ns/1ns
module tb;
  reg clk = 0;
  reg rst = 0;
  reg [{N}*{E}-1:0] charge = 0;
  wire frame_valid;
  wire [{N}*{WD}-1:0] frame;
  reg [{N}*{E}-1:0] pre [0:{P}-1];
  reg [{N}*{E}-1:0] stim [0:{T}-1];
  integer t;
  {TOP} dut (.clk(clk), .rst(rst), .charge(charge), .frame_valid(frame_valid), .frame(frame));
  always #5 clk = ~clk;
  initial begin
    $readmemh("pre.hex", pre);
    $readmemh("stim.hex", stim);
    // run on junk without reset, then one reset clock: t = 0 is the next edge
    for (t = 0; t < {P}; t = t + 1) begin charge = pre[t]; @(negedge clk); end
    rst = 1; charge = pre[0]; @(negedge clk);
    if (frame_valid !== 1'b0) $display("BAD frame_valid after reset");
    rst = 0;
    for (t = 0; t < {T}; t = t + 1) begin
      charge = stim[t];
      @(negedge clk);                       // the rising edge in between processed clock t
      if (frame_valid === 1'b1) $display("%0d %h", t, frame);
      else if (frame_valid !== 1'b0) $display("BAD frame_valid %b", frame_valid);
    end
    $finish;
  end
endmodule
"""


def iverilog_words(config, stimulus, pre, tmp_path, verilog=None):
    """Run the generated top in Icarus, driving only the SPEC ports; return words and clocks."""
    T, H, W = stimulus.shape
    e, wd = config.input_bits, config.word_bits
    top = "te_pixel_array" if config.is_te else "ml_pixel_array"
    digits = (H * W * e + 3) // 4

    def hexlines(frames):
        lines = []
        for frame in frames:
            v = 0
            for i, x in enumerate(frame.ravel()):
                v |= int(x) << (i * e)
            lines.append(f"{v:0{digits}x}")
        return "\n".join(lines) + "\n"

    (tmp_path / "pre.hex").write_text(hexlines(pre))
    (tmp_path / "stim.hex").write_text(hexlines(stimulus))
    (tmp_path / "A.v").write_text(verilog or generated(config, H, W))
    (tmp_path / "tb.v").write_text(TESTBENCH.format(N=H * W, E=e, WD=wd, P=len(pre), T=T, TOP=top))
    build = run(["iverilog", "-g2005", "-o", "sim.vvp", "tb.v", "A.v"], tmp_path)
    assert build.returncode == 0, build.stderr
    sim = run(["vvp", "-n", "sim.vvp"], tmp_path)
    assert sim.returncode == 0 and "BAD" not in sim.stdout, sim.stdout + sim.stderr
    words, clocks = [], []
    for line in sim.stdout.splitlines():
        m = re.fullmatch(r"(\d+) ([0-9a-fA-F]+)", line.strip())
        if m:
            clocks.append(int(m.group(1)))
            v = int(m.group(2), 16)
            words.append([(v >> (i * wd)) & ((1 << wd) - 1) for i in range(H * W)])
    return np.array(words, np.int64).reshape(-1, H, W), clocks


@needs["iverilog"]
@pytest.mark.parametrize("config", [EDGE_CONFIGS[i] for i in (0, 1, 4, 8)] + [MSB_CONFIGS[i] for i in (0, 3, 4)],
                         ids=str)
def test_iverilog_run_equals_golden(config, tmp_path, rng):
    stim = mixed_stimulus(config, rng, 3, 2, 3)
    pre = mixed_stimulus(config, rng, 1, 2, 3)[:37]       # junk before the reset, mid-interval
    words, clocks = iverilog_words(config, stim, pre, tmp_path)
    L = config.clocks_per_readout
    assert clocks == [(k + 1) * L - 1 for k in range(3)]
    assert np.array_equal(words, step_reference(config, stim)[0])


@needs["iverilog"]
def test_blocked_generate_loops_equal_golden(tmp_path, rng, monkeypatch):
    """Rows/columns longer than LOOP_BLOCK (Verilator's unroll limit) use guarded blocks."""
    import tespike.rtl.verilog
    from tespike import rtl
    monkeypatch.setattr(rtl.verilog, "LOOP_BLOCK", 2)
    config = SensorConfig(b1=2, b2=2, clocks_per_tick=2, threshold=30)       # L = 6
    text = array_verilog(config, 3, 5)
    assert "row_block" in text and "col_block" in text and "in_range" in text
    stim = mixed_stimulus(config, rng, 4, 3, 5)
    words, clocks = iverilog_words(config, stim, stim[:3], tmp_path, verilog=text)
    assert clocks == [5, 11, 17, 23]
    assert np.array_equal(words, step_reference(config, stim)[0])
    if shutil.which("verilator"):
        lint = run(["verilator", "--lint-only", "-Wall", "A.v"], tmp_path)
        assert lint.returncode == 0, lint.stderr


def test_array_verilog_has_no_number_wider_than_verilators_default_limit():
    """Verilator refuses a number wider than its --max-num-width (65536 bits by
    default): an H*W*E-bit initial value broke every paper TE array above 4096
    pixels. No literal in the text may grow with the array."""
    for height, width in ((128, 128), (256, 512)):
        text = array_verilog(SensorConfig(), height, width)
        widths = [int(w) for w in re.findall(r"\b(\d+)'[bdhoBDHO]", text)]
        assert widths and max(widths) <= 64, max(widths)


@needs["verilator"]
def test_array_above_4096_pixels_lints_under_verilators_defaults(tmp_path):
    # 64 x 128 paper TE pixels: 131072 input bits (about 30 s, 1.1 GB)
    (tmp_path / "A.v").write_text(array_verilog(SensorConfig(), 64, 128))
    lint = run(["verilator", "--lint-only", "-Wall", "A.v"], tmp_path)
    assert lint.returncode == 0 and "%Warning" not in lint.stderr, lint.stderr[:2000]


def test_an_interrupt_while_yosys_runs_leaves_no_process_and_no_open_pipe():
    """Amaranth's Yosys helper waits for Yosys with ``communicate``: an interrupt there (Ctrl-C,
    SIGTERM) kills and closes the Yosys process (it used to run on, its pipes left for Python
    to warn of at exit). Each process Yosys's helper starts waits 3 s first (one process, exec'd
    into the command): on an idle machine the real run took under the 0.2 s the interrupt
    waits, and the interrupt came after it."""
    import subprocess
    import sys
    body = ("import gc, os, signal, threading, time, warnings\n"
            "signal.signal(signal.SIGINT, signal.default_int_handler)\n"   # (a background job inherits it ignored)
            "warnings.simplefilter('always')\n"
            "from tespike.golden.config import SensorConfig\n"
            "from tespike.rtl.verilog import array_verilog\n"
            "from amaranth._toolchain import yosys\n"
            "import subprocess, sys\n"
            "class SlowPopen(subprocess.Popen):\n"
            "    def __init__(self, args, *rest, **kw):\n"
            "        wait = 'import os, sys, time; time.sleep(3); os.execvp(sys.argv[1], sys.argv[1:])'\n"
            "        super().__init__([sys.executable, '-c', wait, *args], *rest, **kw)\n"
            "subprocess.Popen = SlowPopen\n"
            "started = []\n"
            "real = yosys.subprocess.Popen\n"
            "main = threading.get_ident()\n"
            "def children():\n"
            "    with open(f'/proc/{os.getpid()}/task/{os.getpid()}/children') as f:\n"
            "        return f.read().split()\n"
            "def interrupt_once_yosys_runs():\n"   # (a fixed delay may come before or after it)
            "    while not children():\n"
            "        time.sleep(0.01)\n"
            "    time.sleep(0.2)\n"
            "    signal.pthread_kill(main, signal.SIGINT)\n"
            "threading.Thread(target=interrupt_once_yosys_runs, daemon=True).start()\n"
            "try:\n"
            "    array_verilog(SensorConfig(), 3, 3)\n"
            "except KeyboardInterrupt:\n"
            "    print('interrupted')\n"
            "gc.collect()\n"
            "print('children', len(children()), 'restored', yosys.subprocess.Popen is real)\n")
    done = subprocess.run([sys.executable, "-c", body], capture_output=True, text=True, timeout=120)
    assert done.stdout == "interrupted\nchildren 0 restored True\n", (done.stdout, done.stderr)
    assert "ResourceWarning" not in done.stderr, done.stderr


def test_the_rtl_builders_refuse_flags_names_lanes_and_configurations_that_are_none_in_one_line():
    """``TEPixel(config, word_register='False')`` built a word register and ``flat='yes'`` a flat
    array; a module name with a space was Yosys's parser error; ``beat_layout(config, -1)`` was
    Amaranth's TypeError and 0 lanes were taken; a preset's name an AttributeError; an unknown view a
    plain ValueError."""
    from tespike.golden.config import SensorConfig
    from tespike.golden.errors import ConfigError
    from tespike.rtl.array import PixelArray
    from tespike.rtl.names import module_names, stream_module_names
    from tespike.rtl.pixel import MLPixel, TEPixel, pixel_class
    from tespike.rtl.stream import beat_layout
    from tespike.rtl.verilog import pixel_verilog, timing_verilog
    from tespike.rtl.verilog_stream import stream_array_verilog
    te, ml = SensorConfig(), SensorConfig(mode="ml")
    for make, what in ((lambda: TEPixel(te, word_register="False"), "TEPixel word_register = 'False'"),
                       (lambda: MLPixel(ml, word_register=1), "MLPixel word_register = 1"),
                       (lambda: PixelArray(te, 2, 2, flat="yes"), "PixelArray flat = 'yes'")):
        with pytest.raises(ConfigError, match=f"^{what}: must be True or False$"):
            make()
    for write in (pixel_verilog, timing_verilog):
        for name in ("my pixel", 3, "1pixel"):
            with pytest.raises(ConfigError, match=f"^module name {name!r}: must be a Verilog identifier"):
                write(te, name)
    for lanes in (-1, 2.5, 0):
        with pytest.raises(ConfigError, match=f"^lanes = {lanes!r}: must be an integer >= 1$"):
            beat_layout(te, lanes)
    for call, what in ((pixel_class, "pixel_class"), (module_names, "module_names"),
                       (stream_module_names, "stream_module_names"), (lambda c: beat_layout(c, 2), "beat_layout")):
        with pytest.raises(ConfigError, match=f"^{what}: configuration must be a SensorConfig"):
            call("te")
    with pytest.raises(ConfigError, match="^view = 'nope': one of instances, loop$"):
        stream_array_verilog(te, 2, 2, 2, view="nope")
