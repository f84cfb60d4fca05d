"""golden.atomic's work folders: gone however the run ends, and never reported as outputs."""

import os
import signal
import subprocess
import sys
import time

from tespike.golden.atomic import atomic_output, finished_outputs, work_folder
from tests.cli import _checkout_env


def test_a_work_folder_goes_when_its_block_ends_and_holds_no_output(tmp_path):
    since = len(finished_outputs())
    with work_folder("tespike-test-", tmp_path) as folder:
        with atomic_output(folder / "inside.txt") as tmp:
            open(tmp, "w").write("intermediate")
        assert (folder / "inside.txt").read_text() == "intermediate"
    with atomic_output(tmp_path / "out.txt") as tmp:
        open(tmp, "w").write("result")
    assert not folder.exists()
    assert finished_outputs(since) == [str(tmp_path / "out.txt")]   # (an interrupt names this one only)


def test_a_work_folder_of_a_run_killed_outright_is_removed(tmp_path):
    """SIGKILL runs no ``finally``: the janitor removes the folder (tempfile.TemporaryDirectory
    left prove's, synthesize's and the simulators' folders behind)."""
    body = ("import sys, time\n"
            "from tespike.golden.atomic import work_folder\n"
            f"with work_folder('tespike-test-', {str(tmp_path)!r}) as folder:\n"
            "    (folder / 'tool-input.v').write_text('module m; endmodule')\n"
            "    print(folder, flush=True)\n"
            "    time.sleep(60)\n")
    process = subprocess.Popen([sys.executable, "-c", body], stdout=subprocess.PIPE, text=True,
                               env=_checkout_env())
    folder = process.stdout.readline().strip()
    assert os.path.isdir(folder)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    end = time.monotonic() + 10
    while os.path.exists(folder) and time.monotonic() < end:
        time.sleep(0.02)
    assert not os.path.exists(folder)


def test_a_stop_as_a_temporary_is_made_leaves_none_behind(tmp_path, monkeypatch):
    """Ctrl-C (or SIGTERM) right after the temporary was made, before the block that removes it
    began: the temporary stayed (CI caught an rtl-sim SIGTERM leaving '.w.vcd.<pid>.<x>.part')."""
    import tempfile

    import pytest

    from tespike.golden.atomic import atomic_folder
    real_file, real_folder = tempfile.mkstemp, tempfile.mkdtemp

    def then_stopped(real):
        def made(*args, **kwargs):
            made_path = real(*args, **kwargs)
            signal.raise_signal(signal.SIGINT)          # (Python's handler: KeyboardInterrupt at once)
            return made_path
        return made
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        monkeypatch.setattr(tempfile, "mkstemp", then_stopped(real_file))
        with pytest.raises(KeyboardInterrupt):
            with atomic_output(tmp_path / "out.npy"):
                pass
        monkeypatch.setattr(tempfile, "mkdtemp", then_stopped(real_folder))
        with pytest.raises(KeyboardInterrupt):
            with atomic_folder(tmp_path / "results"):
                pass
        with pytest.raises(KeyboardInterrupt):
            with work_folder("tespike-test-", dir=tmp_path):
                pass
    finally:
        signal.signal(signal.SIGINT, previous)
    assert os.listdir(tmp_path) == []


def test_a_results_folder_removed_during_the_run_is_not_moved_into_place_half_filled(tmp_path):
    """``demo --out X/DM`` with ``X`` removed mid-run: a writer's ``mkdir(parents=True)`` made the hidden
    folder again, the files written after went into it, and it was moved into place, exit 0."""
    import shutil

    import pytest

    from tespike.golden.atomic import atomic_folder
    from tespike.golden.errors import InputError
    holder = tmp_path / "X"
    holder.mkdir()
    with pytest.raises(InputError, match=r"cannot write '.*X/DM': the folder it was being built in "
                                         r"\('.*X'\) was removed during the run; nothing written$"):
        with atomic_folder(holder / "DM") as tmp:
            (tmp / "first.txt").write_text("1")
            shutil.rmtree(holder)                   # (another program, mid-run)
            tmp.mkdir(parents=True)                 # (a writer that makes its folder)
            (tmp / "second.txt").write_text("2")
    assert not (holder / "DM").exists() and os.listdir(holder) == []


def test_write_outputs_makes_no_folder_whose_holder_is_gone(tmp_path):
    """write_outputs made its folder with ``parents=True``: a results folder whose holder was removed
    during the run came back, holding only the files written after."""
    import pytest

    from tespike.golden.errors import InputError
    from tespike.recon.report import write_outputs
    from tests.test_recon_evaluate import _hand_made
    with pytest.raises(InputError, match=r"its folder '.*gone' does not exist"):
        write_outputs(_hand_made(), tmp_path / "gone" / "eval")
    assert not (tmp_path / "gone").exists()
