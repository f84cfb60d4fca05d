"""Figures and helpers kept in one place: the copies a review found stay gone, and the places that
must still type a figure (a parser that imports no recon) agree with its one definition."""

from __future__ import annotations

import numpy as np
import pytest

from tespike.golden.errors import one_line
from tespike.golden.light import DARK_NORMAL, dark_electrons, eq13_dark_per_readout
from tespike.golden.noise import model_mean


def test_one_line_collapses_names_empty_messages_and_cuts():
    assert one_line(ValueError("a\n  b\tc")) == "a b c"
    assert one_line(KeyError()) == "KeyError"
    assert one_line(OSError("x" * 250)) == "x" * 134 + "..." + "x" * 66
    assert one_line("y" * 120, 100) == "y" * 67 + "..." + "y" * 33
    assert one_line("z" * 100, 100) == "z" * 100
    # the middle is cut: what a message names (its start) and the cause (its end) both stay
    cut = one_line("'f.hdr': EXPOSURE=1" + "0" * 400 + " must hold finite numbers > 0", 100)
    assert cut.startswith("'f.hdr': EXPOSURE=1") and cut.endswith("must hold finite numbers > 0")


def test_dark_models_draw_and_integrate_the_same_parameters():
    """eq. 12's mean is its normal mean; eq. 13's integrated mean agrees with its draws."""
    assert model_mean("eq12") == DARK_NORMAL["eq12"][0]
    mean, sd = DARK_NORMAL["eq13"]
    draws = eq13_dark_per_readout(np.random.default_rng(0).normal(mean, sd, 400_000))
    assert abs(draws.mean() / model_mean("eq13") - 1) < 0.01
    assert eq13_dark_per_readout(np.array([-1.0, 0.0, 1e-300])).tolist() == [0.0, 0.0, 15000.0]
    same = dark_electrons("eq13", (64,), np.random.default_rng(1))
    assert np.array_equal(same, np.rint(eq13_dark_per_readout(np.random.default_rng(1).normal(mean, sd, (64,)))))


def test_train_help_states_the_calibration_readouts(capsys):
    """train_cmd's help states the readouts from the constant (its parser reads recon.calibration, no torch)."""
    from tespike.cosim.cli import build_parser
    from tespike.recon.calibration import CALIBRATION_READOUTS
    from tespike.recon.engine.clips import sensor_calibration
    from tespike.recon.evaluate import CALIBRATION_READOUTS as evaluated

    assert evaluated == CALIBRATION_READOUTS == sensor_calibration.__defaults__[-1]
    with pytest.raises(SystemExit):
        build_parser("train").parse_args(["train", "--help"])
    assert f"a {CALIBRATION_READOUTS}-readout dark stream" in " ".join(capsys.readouterr().out.split())


def test_paper_table10_is_one_table():
    from tespike.recon.baselines import PAPER_PARAMETERS
    from tespike.recon.complexity import PAPER_TABLE10, paper_table10

    assert paper_table10() == PAPER_TABLE10 and set(PAPER_TABLE10) == {"spk2imgnet", "bsf", "mambaspike", "net"}
    assert all(PAPER_TABLE10[m].parameters == PAPER_PARAMETERS[m] for m in ("spk2imgnet", "bsf", "mambaspike"))
    assert (PAPER_TABLE10["net"].parameters, PAPER_TABLE10["net"].flops) == (6_479_000, 3.711e12)
