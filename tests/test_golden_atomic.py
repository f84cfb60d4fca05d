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
