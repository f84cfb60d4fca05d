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
