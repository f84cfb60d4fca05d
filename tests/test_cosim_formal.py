"""``tespike prove``: the pixel's proofs pass, and fail (with a VCD) when its rule is broken."""

import json
import shutil
from dataclasses import replace
from types import SimpleNamespace

import pytest
from amaranth.hdl import Const, Module

import tespike.rtl.pixel
from tespike import rtl
import tespike.rtl.verilog_stream
from tespike import rtl
from tespike.cosim.formal import ProofToolError, corners, properties, prove, require_tools, stream_rule_equivalence
from tespike.golden.config import SensorConfig, load_config
from tests.cli import assert_refused, run_tespike

pytestmark = pytest.mark.skipif(
    not all(shutil.which(tool) for tool in ("yosys", "yosys-smtbmc", "z3")),
    reason="yosys, yosys-smtbmc and z3 are needed (install.sh installs them)")

SMALL_TE = corners("te")["min"]


def _prove_all(config, tmp_path, pixel_factory=None):
    return {name: prove(name, build(), depth=2, solver="z3", trace_dir=tmp_path)
            for name, build in properties(config, pixel_factory).items()}


def test_small_te_and_ml_corners_are_proved(tmp_path):
    for config in (SMALL_TE, corners("ml", "msb")["min"]):
        results = _prove_all(config, tmp_path)
        assert all(r.proved for r in results.values()), results


class LateSpikeTEPixel(rtl.pixel.TEPixel):
    """A broken pixel: it fires one electron late (threshold + 1)."""

    def elaborate(self, platform):
        m = Module()
        rtl.pixel.te_pixel_logic(m, replace(self.config, threshold=self.config.threshold + 1),
                                 self.charge, self.ccc, self.last, self.word,
                                 word_register=self.word_register, clear=self.clear)
        return m


def test_a_broken_pixel_fails_with_a_counterexample_trace(tmp_path):
    config = SensorConfig(mode="te", b1=2, b2=2, threshold=3, acc_bits=3, input_bits=2)
    results = _prove_all(config, tmp_path, LateSpikeTEPixel)
    rule = results["rule"]
    assert not rule.proved and rule.trace is not None and rule.trace.stat().st_size > 0
    assert "acc" in rule.detail or "word" in rule.detail, rule.detail
    assert "charge" in rule.trace.read_text()
    # the same config with the real pixel is proved: the failure is the mutation's
    assert all(r.proved for r in _prove_all(config, tmp_path).values())


def test_msb_remainder_dropped_is_caught(tmp_path, monkeypatch):
    """Monkeypatched rule: the msb readout forgets the rest of the count (SPEC says it stays)."""
    real = rtl.pixel._msb_readout

    def forgetful(m, count, bits, name, named):
        index, _ = real(m, count, bits, name, named)
        return index, Const(0, bits)
    monkeypatch.setattr(rtl.pixel, "_msb_readout", forgetful)
    config = SensorConfig(mode="ml", ml_readout="msb", ml_bits=3, threshold=2, acc_bits=2, input_bits=2)
    results = _prove_all(config, tmp_path)
    assert not results["rule"].proved and "count" in results["rule"].detail


class WrappingMLPixel(rtl.pixel.MLPixel):
    """A broken pixel: its counter wraps past 2^ml_bits - 1 instead of saturating."""

    def elaborate(self, platform):
        c = self.config
        wraps = SimpleNamespace(ml_bits=c.ml_bits, ml_max=2 ** c.ml_bits, is_msb=c.is_msb,
                                threshold=c.threshold, acc_bits=c.acc_bits, acc_max=c.acc_max,
                                input_bits=c.input_bits)
        m = Module()
        rtl.pixel.ml_pixel_logic(m, wraps, self.charge, self.last, self.word,
                                 word_register=self.word_register, clear=self.clear)
        return m


def test_a_silently_wrapping_counter_fails_the_bounds(tmp_path):
    config = SensorConfig(mode="ml", ml_bits=2, threshold=1, acc_bits=1, input_bits=1)
    results = _prove_all(config, tmp_path, WrappingMLPixel)
    assert not results["bounds"].proved and "never wraps" in results["bounds"].detail
    assert results["bounds"].trace is not None


def test_command_proves_a_config_and_reports_each_property(tmp_path):
    path = tmp_path / "small.json"
    path.write_text(json.dumps(SMALL_TE.to_dict()))
    done = run_tespike("prove", "--config", path, "--depth", "2", "--only", "pixel", timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert [line.split(":")[0] for line in lines[:-1]] == ["small rule", "small rule-registered-word",
                                                            "small bounds", "small stream",
                                                            "small stream-pixel-rule"]
    assert all("proved" in line for line in lines[:-1]) and "5 of 5 properties proved" in lines[-1]


def test_a_missing_tool_is_named_with_its_package(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None if name == "yosys-smtbmc" else "/bin/" + name)
    with pytest.raises(ProofToolError, match=r"'yosys-smtbmc' is not on PATH.*apt-get install yosys"):
        require_tools("z3")


def test_tops_alone_need_no_smt_solver(tmp_path):
    """``--only tops`` runs ABC: a PATH with yosys and yosys-abc alone (no z3, no yosys-smtbmc)
    proves the timing blocks; the pixel's proofs on the same PATH name the missing tool."""
    for tool in ("yosys", "yosys-abc"):
        (tmp_path / tool).symlink_to(shutil.which(tool))
    path = {"PATH": str(tmp_path)}
    done = run_tespike("prove", "--config", "te", "--only", "tops", "--sizes", "none", "--config-sizes", "none",
                       env=path, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "4 of 4 properties proved" in done.stdout
    assert_refused(run_tespike("prove", "--config", "te", "--only", "pixel", env=path, timeout=300),
                   "'yosys-smtbmc' is not on PATH")


def test_ctrl_c_ends_the_proof_pool_at_any_moment(tmp_path):
    """The terminal's Ctrl-C reaches the workers too: one interrupted inside the pool's queue
    lock left the command waiting on it forever (2 runs of 5 hung). Now the workers leave the
    signal to the command, which ends them: one line, exit 130, no work folder left."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from tests.cli import _checkout_env
    from tests.processes import interruptible
    env = dict(_checkout_env(), TMPDIR=str(tmp_path))
    for delay in (0.8, 1.5, 2.5):
        process = subprocess.Popen([sys.executable, "-m", "tespike", "prove", "--corners", "--depth", "3",
                                    "--workers", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                   text=True, env=env, start_new_session=True, preexec_fn=interruptible)
        time.sleep(delay)
        os.killpg(process.pid, signal.SIGINT)               # as a terminal's Ctrl-C: the whole group
        try:
            _, stderr = process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()
            raise AssertionError(f"prove hung after Ctrl-C at {delay} s")
        if process.returncode == 0:                         # (done before the signal: nothing to see)
            continue
        assert process.returncode == 130 and stderr.strip() == "tespike prove: interrupted", stderr
    time.sleep(0.5)
    assert [p.name for p in tmp_path.iterdir()] == []


def test_command_refuses_bad_options_in_one_line(tmp_path):
    done = run_tespike("prove", "--solver", "cvc9", timeout=60)
    assert_refused(done, "cvc9")
    done = run_tespike("prove", "--depth", "0", timeout=60)
    assert_refused(done, "--depth")
    done = run_tespike("prove", "--depth", "100000", timeout=60)       # ran for minutes, nothing printed
    assert_refused(done, "--depth 100000", "1..32")
    done = run_tespike("prove", "--workers", "0", timeout=60)
    assert_refused(done, "--workers")
    # BMC gets 10 s whatever is left: 0.001 s ran for minutes and said "undecided ... in 0.001 s"
    done = run_tespike("prove", "--only", "tops", "--top-timeout", "0.001", timeout=60)
    assert_refused(done, "--top-timeout 0.001", "at least 10 seconds")
    # two sensors of one name: the later replaced the earlier, which was never proved (exit 0)
    done = run_tespike("prove", "--only", "pixel", "--config", "te", "--config", "other/te.json", timeout=60)
    assert_refused(done, "a sensor named 'te' is already given")
    # a size named twice was proven once, without a word
    done = run_tespike("prove", "--only", "tops", "--sizes", "1x1,1x1", timeout=60)
    assert_refused(done, "--sizes '1x1,1x1'", "1x1 is named more than once")
    # a --traces that is a file was found only when a failure's trace was written, after the proofs
    done = run_tespike("prove", "--only", "pixel", "--traces", __file__, timeout=60)
    assert_refused(done, "--traces", "is not a directory")
    # a trace a failure would write: a folder in its place was found after the proofs, and a link
    # from its place to the --config file had the counterexample written over the configuration
    (tmp_path / "tr" / "te-stream.vcd").mkdir(parents=True)
    assert_refused(run_tespike("prove", "--only", "pixel", "--traces", tmp_path / "tr", timeout=60),
                   "cannot write --traces", "te-stream.vcd", "it is a directory")
    config = tmp_path / "mine.json"
    config.write_text(SensorConfig().to_json())
    (tmp_path / "links").mkdir()
    (tmp_path / "links" / "mine-stream.vcd").symlink_to(config)
    assert_refused(run_tespike("prove", "--only", "pixel", "--config", config, "--depth", "1",
                               "--traces", tmp_path / "links", timeout=60),
                   "a counterexample of --traces", "mine-stream.vcd", "is the same file as --config")
    assert config.read_text() == SensorConfig().to_json()
    # the other part's options with --only were dropped without a word (exit 0)
    for only, option in (("pixel", ("--sizes", "2x2")), ("pixel", ("--config-sizes", "none")),
                         ("pixel", ("--top-timeout", "1")), ("tops", ("--depth", "5")), ("tops", ("--corners",))):
        assert_refused(run_tespike("prove", "--only", only, *option, timeout=60), option[0], f"--only {only}")


# -- the streaming Verilog top's pixel rule (rtl/verilog_stream.py) --------------------------------
PRESETS = ("te", "ml", "ml-msb")

#: Hand edits of the streaming top's rule text, per preset: (what is replaced, by what).
MUTATIONS = {
    "te": [(">=", ">"),                           # fires one electron late
           ("m_next = total[4]", "m_next = total[3]"),   # latches the CCC on the wrong bit
           ("{1'b1, m_next}", "{1'b0, m_next}")],  # loses the flag in the word
    "ml": [(">=", ">"), ("count[p] + 8'd1", "count[p] + 8'd2")],
    "ml-msb": [(">=", ">"), ("(word - 4'd1)", "word"),   # keeps the wrong remainder
               ("word = 4'd2", "word = 4'd3")],           # a wrong msb index
}


def _mutated(monkeypatch, old: str, new: str) -> None:
    real = rtl.verilog_stream._pixel_rule

    def edited(config, indent):
        decls, body = real(config, indent)
        assert old in body, (old, body)
        return decls, body.replace(old, new, 1)
    monkeypatch.setattr(rtl.verilog_stream, "_pixel_rule", edited)


@pytest.mark.parametrize("preset", PRESETS)
def test_stream_pixel_rule_is_the_tops_text_and_equivalent(preset, tmp_path):
    config = load_config(preset)
    decls, body = rtl.verilog_stream._pixel_rule(config, rtl.verilog_stream.RULE_INDENT)
    module = rtl.verilog_stream.stream_pixel_rule_verilog(config)
    top = rtl.verilog_stream.stream_top_verilog(config, 2, 3, 2)
    assert decls in module and body in module and decls in top and body in top
    result = prove(f"{preset}-stream-pixel-rule", stream_rule_equivalence(config), depth=1,
                   solver="z3", trace_dir=tmp_path)
    assert result.proved, result.detail


@pytest.mark.parametrize("preset,old,new", [(p, o, n) for p, edits in MUTATIONS.items() for o, n in edits])
def test_an_edited_stream_pixel_rule_fails_with_a_counterexample(preset, old, new, tmp_path, monkeypatch):
    _mutated(monkeypatch, old, new)
    config = load_config(preset)
    assert new in rtl.verilog_stream.stream_top_verilog(config, 2, 3, 2)   # the top has the edit too
    result = prove(f"{preset}-stream-pixel-rule", stream_rule_equivalence(config), depth=1,
                   solver="z3", trace_dir=tmp_path)
    assert not result.proved
    assert result.detail.startswith("equivalence check: ") and "(pixel) vs" in result.detail, result.detail
    assert " at " in result.detail and "charge=" in result.detail, result.detail
    assert result.trace is not None and "in_charge" in result.trace.read_text()


def test_command_fails_in_one_line_on_an_edited_stream_rule(tmp_path, monkeypatch, capsys):
    from tespike.cosim.cli import main

    _mutated(monkeypatch, ">=", ">")
    path = tmp_path / "small.json"
    path.write_text(json.dumps(SMALL_TE.to_dict()))
    code = main(["prove", "--config", str(path), "--depth", "2", "--only", "pixel",
                 "--traces", str(tmp_path / "traces")])
    out = capsys.readouterr().out.strip().splitlines()
    assert code == 1
    failed = [line for line in out if "FAILED" in line]
    assert len(failed) == 1 and failed[0].startswith("small stream-pixel-rule: FAILED") \
        and "in the equivalence check: " in failed[0], out
    assert (tmp_path / "traces" / "small-stream-pixel-rule.vcd").exists()
    assert "4 of 5 properties proved" in out[-1]


def test_an_induction_step_failing_at_too_small_a_depth_is_inconclusive(tmp_path, capsys):
    """``--depth 1`` printed 'stream: FAILED ...; counterexample' for a design proved at depth 2: an
    induction step's failure may start from a state no run reaches, so it is 'NOT PROVED'."""
    from tespike.cosim.cli import main

    path = tmp_path / "small.json"
    path.write_text(json.dumps(SMALL_TE.to_dict()))
    code = main(["prove", "--config", str(path), "--depth", "1", "--only", "pixel", "--workers", "1",
                 "--traces", str(tmp_path / "traces")])
    out = capsys.readouterr().out.strip().splitlines()
    assert code == 1 and not [line for line in out if "FAILED" in line], out
    stuck = [line for line in out if "NOT PROVED" in line]
    assert stuck and all("inconclusive" in line and "--depth" in line for line in stuck), out


def test_properties_refuse_what_is_no_configuration():
    """(A preset's name had been an AttributeError on its first field read.)"""
    from tespike.cosim.formal import properties
    from tespike.golden.errors import ConfigError
    with pytest.raises(ConfigError, match="^properties: configuration must be a SensorConfig"):
        properties("te")


def test_the_proof_builders_refuse_what_would_prove_nothing_in_one_line(tmp_path):
    """prove(..., depth=0) had reported a proved property as failing, with a counterexample of
    nothing; bounds and depths of 0, -5 or 2.5 were taken (0 as the default); a preset's name was an
    AttributeError of ``check``, 0 lanes a ZeroDivisionError, a pixel factory of None "not callable"."""
    from tespike.cosim.formal import prove, rule_harness, stream_lanes
    from tespike.cosim.formal.reference import reference_verilog
    from tespike.cosim.formal.tops import bmc_bound, small_clocks, timing_harness, verilog_parallel_harness
    from tespike.golden.errors import ConfigError, InputError
    small = small_clocks(SensorConfig())
    for depth in (0, -1, 2.5, True):                    # (refused before the harness is looked at)
        with pytest.raises(InputError, match=f"^depth {depth!r}: must be an integer >= 1"):
            prove("rule", None, depth=depth, solver="z3", trace_dir=tmp_path)
    with pytest.raises(InputError, match="^solver 'cvc9': must be one of z3$"):
        prove("rule", None, depth=3, solver="cvc9", trace_dir=tmp_path)
    with pytest.raises(ProofToolError, match=r"^--solver \['z3'\]: must be one of z3$"):    # (a TypeError)
        require_tools(["z3"])
    from tespike.cosim.formal.abc import MIN_BMC_SECONDS, prove_harness
    for timeout in ("5", 1.0, float("nan"), -300):      # (text failed at a subtraction; 1 s was overrun)
        with pytest.raises(InputError, match=f"^timeout {timeout!r}: must be a number of seconds of at least "
                                             f"{MIN_BMC_SECONDS:g}$"):
            prove_harness("timing", None, timeout=timeout)
    for bound in (0, -5, 2.5):
        with pytest.raises(InputError, match=f"^bound {bound!r}: must be an integer >= 1 clocks"):
            verilog_parallel_harness(small, 1, 1, bound=bound)
        with pytest.raises(InputError, match=f"^depth {bound!r}: must be an integer >= 1 clocks"):
            timing_harness(small, depth=bound)
    with pytest.raises(InputError, match="^bmc_bound: lanes 0 must be an integer >= 1"):
        bmc_bound(small, 1, 1, 0)
    with pytest.raises(InputError, match="^reference_verilog parallel_delay -1: must be an integer >= 0$"):
        reference_verilog(small, 1, 1, parallel_delay=-1)
    for call, what in ((lambda c: verilog_parallel_harness(c, 1, 1), "verilog_parallel_harness"),
                       (timing_harness, "timing_harness"), (lambda c: bmc_bound(c, 1, 1, None), "bmc_bound"),
                       (small_clocks, "small_clocks"), (stream_lanes, "stream_lanes"),
                       (lambda c: rule_harness(c, None, False), "pixel harness")):
        with pytest.raises(ConfigError, match=f"^{what}: configuration must be a SensorConfig"):
            call("te")
