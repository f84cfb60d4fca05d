"""``tespike train`` faults (issue 28): each ends in one line naming the file and the cause, a non-zero
exit, no traceback, no orphan worker, no repeated log rows and no lost weights.

In-process where the trainer's own refusal is the point (tiny clips, no worker
processes); as a subprocess where a signal or a killed trainer is.
"""

from __future__ import annotations

import csv
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from tespike.golden.errors import InputError
from tespike.recon.learned import load_weights
from tespike.recon.train import RunFolderGone, train
from tests.cli import ROOT, assert_refused, run_tespike
from tests.test_cli_hardening import small_tmpfs
from tests.test_recon_train import options
from tests.processes import alive, children, interruptible


def log_steps(path) -> list[int]:
    with open(path, newline="") as handle:
        return [int(row["step"]) for row in csv.DictReader(handle)]


def test_full_disk_names_the_file_torch_could_not_write(tmp_path):
    """torch's own writer fails on a full disk with an internal error; the trainer names the file."""
    with small_tmpfs(tmp_path / "small", "256k") as mount:
        with pytest.raises(InputError, match=r"cannot write '.*small/w\.pt': No space left on device"):
            train(options(steps=1), mount / "w.pt")
        assert not [name for name in os.listdir(mount) if name.endswith(".part")]
        with pytest.raises(InputError, match=r"cannot write '.*checkpoint\.pt': No space left on device"):
            train(options(steps=1), tmp_path / "v.pt", work_dir=mount / "v.run")
        assert load_weights(tmp_path / "v.pt")[2]["steps"] == 1         # the weights were written first


def test_empty_or_truncated_files_are_named(tmp_path):
    (tmp_path / "empty.pt").write_bytes(b"")
    with pytest.raises(InputError, match=r"--init file '.*empty\.pt' is empty \(0 bytes\)"):
        train(options(steps=1, init=str(tmp_path / "empty.pt")), tmp_path / "e.pt")
    assert not (tmp_path / "e.run").exists()                             # no empty run folder left
    train(options(steps=1), tmp_path / "w.pt")
    checkpoint = tmp_path / "w.run" / "checkpoint.pt"
    data = checkpoint.read_bytes()
    for cut in (len(data) // 2, 10, 0):
        checkpoint.write_bytes(data[:cut])
        words = "file '.*w\\.run/checkpoint\\.pt' is empty" if cut == 0 else \
            "'.*w\\.run/checkpoint\\.pt' is not a training checkpoint"
        with pytest.raises(InputError, match=f"checkpoint {words}"):
            train(options(steps=2), tmp_path / "w.pt", resume=True)


@pytest.mark.parametrize("text", [b"hello\n", b"step,epoch,lr,loss,seconds\n1,1,0.0001,0.05,0.3\n",
                                  b"\x80\x02}q\x00.", b"PK\x03\x04 cut"])
def test_a_text_or_foreign_file_as_weights_is_named(tmp_path, text):
    """torch's loader for files that are not zip archives read text as its legacy pickle and
    failed with KeyError: 101 ("hello") or IndexError (a run's log.csv): a traceback from
    reconstruct, evaluate and demo --weights, train --init and a text checkpoint on --resume."""
    from tespike.recon.learning.weights import read_weights
    (tmp_path / "w.txt").write_bytes(text)
    with pytest.raises(InputError, match=r"weights '.*w\.txt' is not a tespike weights file \(.*\)$"):
        read_weights(tmp_path / "w.txt")
    with pytest.raises(InputError, match=r"--init '.*w\.txt' is not a tespike weights file"):
        train(options(steps=1, init=str(tmp_path / "w.txt")), tmp_path / "e.pt")


def test_a_stream_given_as_weights_names_what_the_archive_holds(tmp_path):
    """A zip archive of another kind (a stream S.npz) was named by torch's internal assert text."""
    import numpy as np

    from tespike.recon.learning.weights import read_weights
    np.savez(tmp_path / "S.npz", words=np.zeros((2, 2, 2), np.uint8), config=np.array("{}"))
    with pytest.raises(InputError, match=r"is not a tespike weights file \(a zip archive, but not torch's: it "
                                         r"holds words\.npy, config\.npy\)$"):
        read_weights(tmp_path / "S.npz")


def test_resume_does_not_repeat_the_killed_runs_rows(tmp_path):
    """Rows a killed run logged after its last checkpoint are written again by the resumed run: once."""
    train(options(steps=2), tmp_path / "w.pt")
    log = tmp_path / "w.run" / "log.csv"
    with open(log, "a", newline="") as handle:                          # steps 3 and 4, then killed
        csv.writer(handle).writerows([[3, 0, "0.0001", "0.5", "9.0"], [4, 0, "0.0001", "0.5", "9.5"]])
    train(options(steps=4), tmp_path / "w.pt", resume=True)
    assert log_steps(log) == [1, 2, 3, 4]


@pytest.mark.parametrize("cut", ["everything", "the header", "half a row", "the final newline", "a whole row",
                                 "a number's byte", "a header's byte"])
def test_a_cut_run_log_is_refused_or_mended_never_appended_to(tmp_path, cut):
    """A run log emptied or cut: new rows followed no header or joined a stub; a row whole but for
    its newline is kept and the log rewritten. A log cut at a row's end resumed without that step's
    row; one whose number lost a byte ('4t601e-05') trained on and failed drawing the curves at the
    end, with a traceback, weights and checkpoint rewritten."""
    train(options(steps=2), tmp_path / "w.pt")
    log = tmp_path / "w.run" / "log.csv"
    text = log.read_text()
    last = text.rstrip("\n").rsplit("\n", 1)
    log.write_text({"everything": "", "the header": text[:4], "half a row": text[:-12],
                    "the final newline": text.rstrip(), "a whole row": last[0] + "\n",
                    "a number's byte": last[0] + "\n" + last[1].replace(".", "t", 1) + "\n",
                    "a header's byte": text.replace("epoch", "epxch", 1)}[cut])     # (it was resumed under it)
    if cut == "the final newline":
        train(options(steps=3), tmp_path / "w.pt", resume=True)
        assert log_steps(log) == [1, 2, 3]
        return
    with pytest.raises(InputError, match=r"run log '.*log\.csv' is damaged"):
        train(options(steps=3), tmp_path / "w.pt", resume=True)


def test_a_bad_option_is_named_before_the_earlier_run_in_the_run_folder(tmp_path):
    """The run folder's earlier run was said first, and a bad --method or --pool only after --force."""
    train(options(steps=1), tmp_path / "w.pt")
    for option, words in ((("--method", "bogus"), "unknown learned method 'bogus'"), (("--pool", "0"), "pool = 0")):
        done = run_tespike("train", "--config", "te", "--out", tmp_path / "w.pt", "--steps", "1",
                           "--validate-every", "0", *option, timeout=120)
        assert_refused(done, words)


def test_a_validation_log_resumes_and_one_with_its_header_altered_is_refused(tmp_path):
    """Only the header's first cell was checked: a header that lost a byte was resumed under."""
    train(options(steps=1, validate_every=1), tmp_path / "w.pt")
    validation = tmp_path / "w.run" / "validation.csv"
    train(options(steps=2, validate_every=1), tmp_path / "w.pt", resume=True)
    assert log_steps(validation) == [1, 2]
    validation.write_text(validation.read_text().replace("mean", "meax", 1))
    with pytest.raises(InputError, match=r"run log '.*validation\.csv' is damaged"):
        train(options(steps=3, validate_every=1), tmp_path / "w.pt", resume=True)


def test_resuming_a_finished_run_validates_its_last_step_once(tmp_path):
    """A run resumed at its last, validated step validated it again: a second row of that step."""
    train(options(steps=1, validate_every=1), tmp_path / "w.pt")
    validation = tmp_path / "w.run" / "validation.csv"
    train(options(steps=1, validate_every=1), tmp_path / "w.pt", resume=True)
    assert log_steps(validation) == [1]


def test_a_stop_while_the_best_is_kept_leaves_a_run_that_resumes(tmp_path, monkeypatch):
    """Ctrl-C after the validation row, before best.pt was written: the checkpoint recorded a best
    whose file did not exist, and --resume refused ("the run's best weights file ... does not exist")."""
    import signal

    import tespike.recon.train as trainer
    real = trainer.cpu_state

    def stopped_while_keeping(*args, **kwargs):         # the Ctrl-C comes as the best is taken
        signal.raise_signal(signal.SIGINT)
        return real(*args, **kwargs)
    monkeypatch.setattr(trainer, "cpu_state", stopped_while_keeping)
    with pytest.raises(KeyboardInterrupt):
        train(options(steps=3, validate_every=1), tmp_path / "w.pt")
    monkeypatch.undo()
    assert (tmp_path / "w.run" / "best.pt").is_file()     # (the row, the best and its file: all three)
    assert log_steps(tmp_path / "w.run" / "validation.csv") == [1]
    train(options(steps=3, validate_every=1), tmp_path / "w.pt", resume=True)
    assert log_steps(tmp_path / "w.run" / "validation.csv") == [1, 2, 3]


def test_a_second_ctrl_c_while_the_checkpoint_is_saved_keeps_the_run(tmp_path, monkeypatch):
    """Two quick Ctrl-Cs: the second stopped the checkpoint the first one was saving, and the run folder
    (its log and its steps) was removed as one that made nothing, the line saying only "interrupted"."""
    import tespike.recon.train as trainer
    real_step, real_save = trainer.TrainingRun.one_step, trainer._save_checkpoint

    def first_stop(run, first_step):
        if run.step == 2:
            raise KeyboardInterrupt
        return real_step(run, first_step)

    def second_stop(*args, **kwargs):                   # pressed again while the checkpoint is written
        signal.raise_signal(signal.SIGINT)
        return real_save(*args, **kwargs)
    monkeypatch.setattr(trainer.TrainingRun, "one_step", first_stop)
    monkeypatch.setattr(trainer, "_save_checkpoint", second_stop)
    with pytest.raises(KeyboardInterrupt) as stopped:
        train(options(steps=4), tmp_path / "w.pt")
    monkeypatch.undo()
    assert any("at step 2: checkpoint" in note for note in getattr(stopped.value, "__notes__", [])), stopped.value
    assert (tmp_path / "w.run" / "checkpoint.pt").is_file()
    train(options(steps=4), tmp_path / "w.pt", resume=True)
    assert log_steps(tmp_path / "w.run" / "log.csv") == [1, 2, 3, 4]


def test_a_run_folder_removed_during_training_keeps_the_weights(tmp_path, monkeypatch):
    import tespike.recon.train as trainer
    draw, calls = trainer.draw_batch, []

    def draw_then_remove(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            shutil.rmtree(tmp_path / "w.run")
        return draw(*args, **kwargs)
    monkeypatch.setattr(trainer, "draw_batch", draw_then_remove)
    with pytest.raises(RunFolderGone, match=r"run folder '.*w\.run' was removed .*wrote the weights to '.*w\.pt'"):
        train(options(steps=3), tmp_path / "w.pt")
    assert load_weights(tmp_path / "w.pt")[2]["steps"] == 3


# ------------------------------------------------------------------ signals, as a user's terminal sends them
def start_training(folder) -> subprocess.Popen:
    """``tespike train`` with one data-engine worker, in a session of its own (its process group
    gets Ctrl-C as a terminal's would)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-m", "tespike", "train", "--config", "te", "--out", str(folder / "w.pt"),
                             "--minutes", "10", "--workers", "1", "--pool", "2", "--refresh", "1", "--crop", "32",
                             "--batch", "1", "--validate-every", "0"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=interruptible)


def wait_for_worker(process, timeout=180) -> list[int]:
    """The trainer's children once its data worker runs (the resource tracker is one more)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        assert process.poll() is None, process.communicate()
        kids = children(process.pid)
        if len(kids) >= 2:
            return kids
        time.sleep(0.2)
    pytest.fail("no data worker started")


def gone(pids, timeout=10) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end and any(alive(p) for p in pids):
        time.sleep(0.1)
    return not any(alive(p) for p in pids)


def test_a_killed_trainer_leaves_no_worker(tmp_path):
    process = start_training(tmp_path)
    try:
        kids = wait_for_worker(process)
        process.kill()
        _, stderr = process.communicate(timeout=60)
        assert gone(kids), [p for p in kids if alive(p)]
        assert "BrokenPipeError" not in stderr and "Traceback" not in stderr, stderr
    finally:
        os.killpg(process.pid, signal.SIGKILL) if process.poll() is None else None


def signal_the_group(folder, number: int, settle: float = 0.0) -> tuple[subprocess.Popen, str, list[int]]:
    """A training run signalled ``number`` as a terminal signals it, to the whole group, ``settle``
    seconds after its data worker runs -> (the ended process, its stderr, its children then)."""
    process = start_training(folder)
    try:
        kids = wait_for_worker(process)
        time.sleep(settle)
        os.killpg(process.pid, number)
        _, stderr = process.communicate(timeout=120)
    finally:
        os.killpg(process.pid, signal.SIGKILL) if process.poll() is None else None
    return process, stderr, kids


def test_a_hangup_of_the_group_is_one_line(tmp_path):
    """A closed terminal's SIGHUP reaches the whole group: the resource tracker died of it, and the one
    started in its place printed a KeyError traceback for each of the pool's semaphores (25 lines)."""
    process, stderr, kids = signal_the_group(tmp_path, signal.SIGHUP, settle=1.0)   # (the worker at its clips)
    assert process.returncode == 129
    assert_refused(subprocess.CompletedProcess([], 129, "", stderr), "terminated by SIGHUP")
    assert gone(kids)


def test_ctrl_c_is_one_line_and_leaves_no_empty_run_folder(tmp_path):
    process, stderr, kids = signal_the_group(tmp_path, signal.SIGINT)
    assert process.returncode == 130
    assert_refused(subprocess.CompletedProcess([], 130, "", stderr), "interrupted")
    assert gone(kids)
    run = tmp_path / "w.run"
    assert not run.exists() or (run / "checkpoint.pt").is_file(), os.listdir(run)
    assert not (tmp_path / "w.pt").exists()


def test_a_bad_frame_of_hdr_is_named_as_the_user_typed_its_folder(capsys, monkeypatch, tmp_path):
    """The recipe records folders absolute (a resumed run may start elsewhere); the refusal names the
    frame under the folder as given, as every other command does."""
    import numpy as np

    from tespike.cosim.cli import main
    from tespike.recon.scenes import write_hdr
    (tmp_path / "frames").mkdir()
    for k in range(2):
        write_hdr(tmp_path / "frames" / f"f{k}.hdr", np.full((16, 16, 3), 0.5, np.float32))
    (tmp_path / "frames" / "f1.hdr").write_bytes(b"")
    monkeypatch.chdir(tmp_path)
    code = main(["train", "--config", "te", "--hdr", "frames", "--steps", "1", "--batch", "1", "--crop", "16",
                 "--workers", "0", "--out", "t.pt"])
    result = subprocess.CompletedProcess([], code, "", capsys.readouterr().err)
    assert_refused(result, "'frames/f1.hdr'", "empty")
    assert str(tmp_path) not in result.stderr and not (tmp_path / "t.pt").exists()


def test_a_batch_that_cannot_fit_is_refused_before_anything_starts(tmp_path):
    """train --batch 100000 started its data engine and was killed by the kernel's out-of-memory
    killer (exit 137, no word); the step's memory is now bounded below up front (the tensors a
    forward pass keeps for backward, measured on two small crops) and refused in one line."""
    result = subprocess.run([sys.executable, "-m", "tespike", "train", "--config", "te", "--out",
                             str(tmp_path / "w.pt"), "--batch", "100000", "--crop", "128", "--steps", "1",
                             "--workers", "0"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert_refused(result, "training net at batch 100000, crop 128", "memory")
    assert not list(tmp_path.iterdir())


def test_the_step_memory_bound_grows_with_batch_and_crop_area():
    from tespike.recon.train import step_memory
    small, batch, crop = (step_memory(options(batch=b, crop=c)) for b, c in ((2, 16), (4, 16), (4, 32)))
    assert 0 < small < batch < crop
    assert abs((crop - batch) - 6 * (batch - small)) <= 8             # batch x crop area, plus what does not grow


def test_a_new_run_over_an_earlier_runs_folder_is_refused_unless_forced(tmp_path, capsys):
    """A new run started in an earlier run's folder removed its logs and best weights at once but
    kept its checkpoint and curves: killed early, the folder mixed two runs and could not be
    resumed. It is refused now (--resume or --force); --force removes every file of the earlier run."""
    from tespike.cosim.cli import main
    from tespike.recon.train import RUN_FILES
    args = ["train", "--out", str(tmp_path / "w.pt"), "--crop", "32", "--batch", "1", "--pool", "2",
            "--validate-every", "0", "--workers", "0", "-q"]
    assert main([*args, "--steps", "2"]) == 0
    run = tmp_path / "w.run"
    before = {name: (run / name).read_bytes() for name in RUN_FILES if (run / name).exists()}
    capsys.readouterr()
    assert main([*args, "--steps", "3", "--seed", "7"]) == 2
    err = capsys.readouterr().err
    assert "holds an earlier run (checkpoint.pt" in err and "--resume" in err and "--force" in err, err
    assert {name: (run / name).read_bytes() for name in before} == before          # untouched
    assert main([*args, "--steps", "3", "--resume", "--force"]) == 2
    (run / "best.pt").write_bytes(b"an earlier run's")       # every earlier file goes with --force
    capsys.readouterr()
    assert main([*args, "--steps", "1", "--seed", "7", "--force"]) == 0
    assert "removed the earlier run's checkpoint.pt, log.csv, best.pt, curves.png" in capsys.readouterr().err
    assert not (run / "best.pt").exists()
    assert log_steps(run / "log.csv") == [1] and load_weights(tmp_path / "w.pt")[2]["steps"] == 1


def test_a_run_killed_before_its_first_checkpoint_does_not_block_the_next(tmp_path, capsys):
    """Killed before its first checkpoint, a run left an empty log.csv alone: --resume had nothing
    to resume and a new run called it an earlier run, each pointing at the other. A new run now
    starts over such logs (saying so), and --resume's refusal names --force."""
    from tespike.cosim.cli import main
    args = ["train", "--out", str(tmp_path / "w.pt"), "--crop", "32", "--batch", "1", "--pool", "2",
            "--validate-every", "0", "--workers", "0", "--steps", "1", "-q"]
    run = tmp_path / "w.run"
    assert main([*args, "--resume"]) == 2                       # no run at all: --force would not help
    err = capsys.readouterr().err
    assert f"no run folder {str(run)!r}" in err and "leave out --resume" in err and "--force" not in err, err
    run.mkdir()
    (run / "log.csv").write_bytes(b"")
    assert main([*args, "--resume"]) == 2
    err = capsys.readouterr().err
    assert "nothing to resume" in err and "start it anew with --force" in err, err
    assert main(args) == 0
    assert "holds only the logs of a run that saved no checkpoint (log.csv): starting anew" in capsys.readouterr().err
    assert log_steps(run / "log.csv") == [1]


def test_a_new_run_refused_for_its_init_removes_nothing_of_the_earlier(tmp_path):
    """``train --force --init BAD``: the earlier run's checkpoint, log and curves were removed, then the
    --init refused: two lines, and the earlier run could no longer be resumed."""
    train(options(steps=2), tmp_path / "w.pt")
    before = sorted(p.name for p in (tmp_path / "w.run").iterdir())
    (tmp_path / "bad.pt").write_text("hello")
    with pytest.raises(InputError, match=r"--init '.*bad\.pt' is not a tespike weights file"):
        train(options(steps=1, init=str(tmp_path / "bad.pt")), tmp_path / "w.pt")
    assert sorted(p.name for p in (tmp_path / "w.run").iterdir()) == before and "checkpoint.pt" in before


def test_a_budget_that_allows_no_step_writes_nothing(tmp_path):
    """``--minutes 1e-300`` ran 0 steps and wrote the untrained weights with the usual success line."""
    with pytest.raises(InputError, match="--minutes 1e-300 ran out before the first step"):
        train(options(steps=None, minutes=1e-300), tmp_path / "w.pt")
    assert not (tmp_path / "w.pt").exists() and not (tmp_path / "w.run").exists()


def test_weights_whose_archive_end_is_damaged_are_called_damaged(tmp_path):
    """A byte of the end record flipped: torch's miniz text, cut mid-word, was quoted as 'another format'."""
    from tespike.golden.config import load_config
    from tespike.recon.learned import weights_path
    from tespike.recon.learning.weights import read_weights
    data = bytearray(weights_path(load_config("te"), "net").read_bytes())
    data[-30] ^= 0xFF
    (tmp_path / "w.pt").write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"\(a damaged archive: PytorchStreamReader failed reading zip archive: "
                                         r"not a ZIP archive\)$"):
        read_weights(tmp_path / "w.pt")


def test_a_run_folder_another_run_writes_is_refused_and_left_alone(tmp_path, capsys):
    """Two runs into one --out had both exited 0 on a run folder whose log, checkpoint and best weights
    mixed the two: a run holds its folder (flock), and another is refused in one line, touching nothing."""
    import fcntl
    import os

    from tespike.cosim.cli import main
    run = tmp_path / "w.run"
    run.mkdir()
    (run / "log.csv").write_text("step,epoch,lr,loss,seconds\n1,0,0.0001,0.5,0.1\n")
    held = os.open(run, os.O_RDONLY | os.O_DIRECTORY)         # another run writing it
    try:
        fcntl.flock(held, fcntl.LOCK_EX)
        for extra in ([], ["--force"], ["--resume"]):
            assert main(["train", "--out", str(tmp_path / "w.pt"), "--crop", "32", "--batch", "1", "--pool", "2",
                         "--validate-every", "0", "--workers", "0", "--steps", "1", "-q", *extra]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and f"run folder {str(run)!r} is held by another process" in err[0], err
            assert sorted(os.listdir(run)) == ["log.csv"] and not (tmp_path / "w.pt").exists()
    finally:
        os.close(held)
