"""Inputs a command could lose or read wrongly: kept inside a folder the run replaces, frames in a folder
order, parts of a frame file, a dark current asked for twice, read-only folders, and paths the terminal
cannot print. Each case exited 0 with an input overwritten, a result changed or an option dropped."""

import os
import stat
from types import SimpleNamespace

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tespike.recon.scenes.hdr_io import list_frames, read_exr, write_hdr
from tests.cli import assert_refused, run_tespike


@pytest.fixture
def scene(tmp_path):
    assert run_tespike("scene", "--name", "sun", "--frames", 2, "--height", 16, "--width", 16,
                       "--out", tmp_path / "I.npy", "-q").returncode == 0
    return tmp_path / "I.npy"


def test_an_input_inside_a_results_folder_the_run_replaces_is_refused(tmp_path, scene):
    out = tmp_path / "ev"
    args = ("evaluate", "--set", "none", "--methods", "tfp", "--ml-count-config", "none", "--out", out, "-q")
    assert run_tespike(*args, "--scene", scene).returncode == 0
    kept = out / "results.csv"
    kept.write_bytes(scene.read_bytes())                 # a scene stored where the results go
    before = kept.read_bytes()
    result = run_tespike(*args, "--scene", kept, "--force")
    assert_refused(result, "--scene", "lies inside --out", "refusing to overwrite an input")
    assert kept.read_bytes() == before


def test_an_input_inside_the_cocotb_work_folder_is_refused(tmp_path):
    from tespike.cosim.commands.common import check_inputs_outside
    work = tmp_path / "wd"
    work.mkdir()
    (work / "icarus.log").write_text("module m; endmodule\n")

    args = SimpleNamespace(work_dir=str(work), verilog=str(work / "icarus.log"), stimulus=None,
                           argv=[str(work / "icarus.log")])
    with pytest.raises(InputError, match="--verilog .* lies inside --work-dir"):
        check_inputs_outside(args, "work_dir", ("verilog", "stimulus"))
    args.verilog = str(tmp_path / "elsewhere.v")
    check_inputs_outside(args, "work_dir", ("verilog", "stimulus"))   # outside (or missing): nothing to refuse


def test_a_word_that_names_the_results_folder_is_no_input(tmp_path, scene, monkeypatch):
    """The check read every option's value as a path: with a folder of the same name in the working
    folder, the command's own name (``demo --out demo`` run twice, the README's first command), ``--set
    default`` or a preset (``--te-config te``) "lay inside --out" and the second run was refused."""
    from tespike.cosim.cli import build_parser
    from tespike.cosim.commands.common import check_inputs_outside
    from tespike.cosim.commands.evaluate_cmd import INPUT_OPTIONS
    monkeypatch.chdir(tmp_path)
    for word in ("evaluate", "default", "te", "tfp"):
        os.mkdir(word)
        args = build_parser("evaluate").parse_args(["evaluate", "--set", "default", "--te-config", "te",
                                                    "--methods", "tfp", "--out", word])
        check_inputs_outside(args, "out", INPUT_OPTIONS)
    demo = build_parser("demo").parse_args(["demo", "--out", "demo"])
    os.mkdir("demo")
    check_inputs_outside(demo, "out", ("weights",))
    args = ("evaluate", "--set", "none", "--scene", scene, "--methods", "tfp", "--ml-count-config", "none",
            "--out", "evaluate", "--force", "-q")
    assert run_tespike(*args).returncode == 0
    result = run_tespike(*args)                          # a second run into its own folder
    assert result.returncode == 0, result.stderr


def test_frames_whose_names_compare_alike_come_in_one_order(tmp_path):
    """f1, f01 and F1 had equal keys: the folder's own order decided the sequence."""
    for order in (("f1", "f01", "F1"), ("F1", "f01", "f1")):
        folder = tmp_path / "-".join(order)
        folder.mkdir()
        for name in order:
            write_hdr(folder / f"{name}.hdr", np.ones((4, 4, 3), np.float32))
    names = {tuple(p.name for p in list_frames(f)) for f in tmp_path.iterdir()}
    assert len(names) == 1
    folder = tmp_path / "sup"
    folder.mkdir()
    for name in ("1\u00b22", "a", "10"):             # a superscript two is text, not a number
        write_hdr(folder / f"{name}.hdr", np.ones((4, 4, 3), np.float32))
    assert [p.stem for p in list_frames(folder)] == ["1\u00b22", "10", "a"]


def test_a_multi_part_exr_frame_is_refused(tmp_path):
    OpenEXR = pytest.importorskip("OpenEXR")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    rgb = np.full((8, 8, 3), 0.5, np.float32)
    parts = [OpenEXR.Part(dict(header, name=n), {"RGB": rgb}, name=n) for n in ("left", "right")]
    with OpenEXR.File(parts) as f:
        f.write(str(tmp_path / "m.exr"))
    with pytest.raises(InputError, match="holds 2 parts"):
        read_exr(tmp_path / "m.exr")


def test_dataset_hdr_refuses_frames_it_would_drop(tmp_path):
    from tespike.cosim.dataset.build import hdr_sources
    seq = tmp_path / "H" / "seq"
    seq.mkdir(parents=True)
    for i in range(2):
        write_hdr(seq / f"f{i}.hdr", np.ones((4, 4, 3), np.float32))
    assert len(hdr_sources(tmp_path / "H")) == 1
    write_hdr(tmp_path / "H" / "top.hdr", np.ones((4, 4, 3), np.float32))
    with pytest.raises(InputError, match="holds the frame 'top.hdr' beside its sequence folders"):
        hdr_sources(tmp_path / "H")
    os.unlink(tmp_path / "H" / "top.hdr")
    (seq / "deeper").mkdir()
    with pytest.raises(InputError, match="holds the folder 'deeper'"):
        hdr_sources(tmp_path / "H")


def test_dark_current_given_with_a_noise_file_is_refused_even_as_none(tmp_path, scene):
    (tmp_path / "n.json").write_text('{"dark_current": "eq12"}')
    for flag in ("--dark-current", "--dark"):
        result = run_tespike("simulate", "--config", "te", "--scene", scene, "--out", tmp_path / "s.npz",
                             flag, "none", "--noise", tmp_path / "n.json", "--seed", 1)
        assert_refused(result, "--dark-current none with --noise")
    assert not (tmp_path / "s.npz").exists()


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="root's view of modes")
def test_a_folder_whose_mode_says_read_only_is_refused_for_root_too(tmp_path, scene):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        assert_refused(run_tespike("simulate", "--config", "te", "--scene", scene, "--out", folder / "s.npz"),
                       "is not writable")
        assert_refused(run_tespike("view", "--input", scene, "--each", "--out", folder / "new"),
                       "parent directory is not writable")
        assert_refused(run_tespike("view", "--input", scene, "--each", "--out", folder), "not writable")
        assert stat.S_IMODE(folder.stat().st_mode) == 0o555 and not any(folder.iterdir())
    finally:
        folder.chmod(0o755)


def test_the_success_line_escapes_a_path_the_terminal_cannot_encode(tmp_path, scene):
    out = tmp_path / "\u00e9.npz"
    result = run_tespike("simulate", "--config", "te", "--scene", scene, "--out", out, "--seed", 1,
                         env={"PYTHONIOENCODING": "ascii"})
    assert result.returncode == 0 and "\\xe9.npz" in result.stdout and result.stderr == "", result
    assert out.is_file()


def test_a_dangling_link_as_an_output_folder_and_a_cache_variable_naming_a_file_are_said_as_such(tmp_path):
    from tespike.cosim.outside import default_cache_root
    from tespike.golden.paths import check_output_dir
    (tmp_path / "link").symlink_to(tmp_path / "missing" / "x.zarr")
    with pytest.raises(InputError, match="symbolic link to .*missing.*which does not exist"):
        check_output_dir(tmp_path / "link", "--out")
    (tmp_path / "loop1").symlink_to(tmp_path / "loop2")           # (said to be a link to nothing: loop2 exists)
    (tmp_path / "loop2").symlink_to(tmp_path / "loop1")
    with pytest.raises(InputError, match=r"'.*loop1': it is a loop of symbolic links \(Too many levels"):
        check_output_dir(tmp_path / "loop1", "--out")
    (tmp_path / "file").write_text("")
    os.environ["TESPIKE_CACHE"], before = str(tmp_path / "file"), os.environ.get("TESPIKE_CACHE")
    try:
        with pytest.raises(InputError, match=r"\$TESPIKE_CACHE .* is not a directory"):
            default_cache_root()
    finally:
        if before is None:
            del os.environ["TESPIKE_CACHE"]
        else:
            os.environ["TESPIKE_CACHE"] = before
