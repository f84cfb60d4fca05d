"""Outside tools and proof workers end with a command killed outright (tespike.cosim.children).

SIGKILL runs no handler of the command, so only the kernel can end what it
started; each test kills a small Python "command" and watches its child.
"""

import os
import signal
import subprocess
import sys
import time

import pytest

from tests.processes import alive

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")


def _kill_command_and_watch(body: str, seconds: float = 10.0) -> bool:
    """Run ``body`` (Python that prints its child's pid and waits), SIGKILL it, and say
    whether the child is still running ``seconds`` later (it is killed afterwards)."""
    proc = subprocess.Popen([sys.executable, "-c", body], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    child = None
    try:
        child = int(proc.stdout.readline())
        assert alive(child)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + seconds
        while alive(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        return alive(child)
    finally:
        if child is not None and alive(child):
            os.kill(child, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()


def test_a_plain_child_outlives_its_killed_parent():
    """The premise: without the request, the kernel leaves the child running."""
    body = ("import subprocess\n"
            "p = subprocess.Popen(['sleep', '30'])\n"
            "print(p.pid, flush=True)\n"
            "p.wait()\n")
    assert _kill_command_and_watch(body, seconds=1.0)


@pytest.mark.parametrize("start", ["run", "popen"])
def test_a_tool_ends_with_the_command_killed_outright(start):
    if start == "popen":
        body = ("from tespike.cosim import children\n"
                "p = children.popen(['sleep', '30'])\n"
                "print(p.pid, flush=True)\n"
                "p.wait()\n")
    else:                                   # run() blocks: the tool prints its own pid
        body = ("from tespike.cosim import children\n"
                "children.run(['sh', '-c', 'echo $$; exec sleep 30'])\n")
    assert not _kill_command_and_watch(body)


def test_a_proof_worker_ends_with_the_command_killed_outright():
    """``tespike prove --workers N``'s pool: each worker asks to end with the command."""
    body = ("import multiprocessing, os, time\n"
            "from concurrent.futures import ProcessPoolExecutor\n"
            "from tespike.cosim.commands.prove_cmd import proof_worker_start\n"
            "def task():\n"
            "    print(os.getpid(), flush=True)\n"
            "    time.sleep(30)\n"
            "pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context('fork'),\n"
            "                           initializer=proof_worker_start, initargs=(os.getpid(),))\n"
            "pool.submit(task).result()\n")
    assert not _kill_command_and_watch(body)


def test_a_proof_worker_leaves_a_signal_the_command_ignores_ignored():
    """The worker hands the group's signals to the command with a handler of its own (exec gives its
    tools the default action); one the command runs with ignored (``nohup``) stays ignored, so a
    Ctrl-C to the group no longer killed the solvers of a run the user had shielded."""
    body = ("import os, signal\n"
            "signal.signal(signal.SIGINT, signal.SIG_IGN)\n"
            "signal.signal(signal.SIGTERM, signal.SIG_DFL)\n"
            "from tespike.cosim.commands.prove_cmd import proof_worker_start\n"
            "proof_worker_start(os.getppid())\n"
            "print(signal.getsignal(signal.SIGINT) is signal.SIG_IGN, callable(signal.getsignal(signal.SIGTERM)))\n")
    done = subprocess.run([sys.executable, "-c", body], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.split() == ["True", "True"], done


def test_a_child_whose_parent_is_already_gone_leaves():
    """The request comes after the fork: a child whose parent went in between leaves at once."""
    body = ("import os, sys\n"
            "from tespike.cosim.children import end_with_parent\n"
            "end_with_parent(os.getppid() + 1 if os.getppid() != 1 else 2)\n"
            "print('still here')\n")
    done = subprocess.run([sys.executable, "-c", body], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and done.stdout == ""


#: A tool that starts a tool of its own (as make starts the compiler) and prints that one's pid.
_GRANDCHILD_TOOL = "['sh', '-c', 'sleep 30 & echo $!; wait']"


@pytest.mark.parametrize("start, left", [("run", True), ("run_group", False)])
def test_what_a_tool_started_ends_with_the_command_killed_outright(start, left):
    """The signal the kernel sends a tool when the command goes does not reach what the tool
    started (make's compilers: ``run`` leaves it running, the control); ``run_group`` puts the
    tool in a process group of its own, which the command's janitor kills."""
    body = ("from tespike.golden.atomic import start_janitor\n"
            "from tespike.cosim import children\n"
            "start_janitor()\n"
            f"children.{start}({_GRANDCHILD_TOOL})\n")
    assert _kill_command_and_watch(body, seconds=1.0 if left else 10.0) == left


def test_a_kill_right_after_the_tool_starts_still_ends_what_it_started():
    """The group is held by the janitor before the tool runs, not after ``Popen`` returns: here
    the command is killed the moment the tool has started, before it could say anything more."""
    body = ("import os, signal, subprocess, time\n"
            "from tespike.golden.atomic import start_janitor\n"
            "from tespike.cosim import children\n"
            "start_janitor()\n"
            "popen = subprocess.Popen\n"
            "def killed_on_return(*args, **kwargs):\n"
            "    process = popen(*args, **kwargs)\n"
            "    time.sleep(0.5)\n"
            "    os.kill(os.getpid(), signal.SIGKILL)\n"
            "children.subprocess.Popen = killed_on_return\n"
            f"children.run_group({_GRANDCHILD_TOOL})\n")
    assert not _kill_command_and_watch(body)


def test_what_a_tool_started_ends_with_an_interrupted_command(tmp_path):
    """Ctrl-C reaches the command alone (the tool's group is its own): the command ends the
    group, the tool and what it started, and the interrupt goes on. The interrupt comes once
    the tool has said what it started (a fixed delay may come before, on a loaded machine)."""
    said = tmp_path / "grandchild"
    body = ("import os, signal, threading, time\n"
            "signal.signal(signal.SIGINT, signal.default_int_handler)\n"   # (as a terminal's; inherited ignored in
            "from tespike.cosim import children\n"                        # a shell's background job)
            "main = threading.get_ident()\n"
            "def interrupt_once_started():\n"
            f"    while not os.path.getsize({str(said)!r}):\n"
            "        time.sleep(0.01)\n"
            "    signal.pthread_kill(main, signal.SIGINT)\n"
            f"with open({str(said)!r}, 'w') as said:\n"
            "    threading.Thread(target=interrupt_once_started, daemon=True).start()\n"
            "    try:\n"
            "        children.run_group(['sh', '-c', 'sleep 300 & echo $!; wait'], stdout=said)\n"
            "    except KeyboardInterrupt:\n"
            "        print('interrupted', flush=True)\n")
    try:                                   # (left running, the tool would wait 300 s: a timeout)
        done = subprocess.run([sys.executable, "-c", body], capture_output=True, text=True, timeout=60)
        assert done.stdout == "interrupted\n", (done.stdout, done.stderr)
        grandchild = int(said.read_text().split()[0])
        deadline = time.monotonic() + 10
        while alive(grandchild) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not alive(grandchild)
    finally:
        for pid in said.read_text().split():
            if alive(int(pid)):
                os.kill(int(pid), signal.SIGKILL)


def test_run_group_returns_what_run_returns():
    """Output, status and the check of ``subprocess.run``; the group ends with the tool."""
    from tespike.cosim import children
    done = children.run_group(["sh", "-c", "echo out; echo err >&2; exit 3"], capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (3, "out\n", "err\n")
    with pytest.raises(subprocess.CalledProcessError):
        children.run_group(["false"], check=True)
    done = children.run_group([sys.executable, "-c", "import sys; print(sys.stdin.read())"], input="in",
                              capture_output=True, text=True)
    assert done.stdout == "in\n"


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL], ids=["INT", "TERM", "KILL"])
def test_the_tools_temporaries_go_with_a_stopped_command(tmp_path, stop):
    """Yosys's ABC writes ``yosys-abc-XXXX/`` in $TMPDIR (Icarus, the compiler, Dask and torch their own):
    a command stopped while they ran left them there. Each command's tools now write in a folder of
    its own that its janitor holds."""
    import glob
    import shutil
    if shutil.which("yosys") is None:
        pytest.skip("Yosys is not installed")
    from tests.cli import _checkout_env
    temporary = tmp_path / "t"
    temporary.mkdir()
    process = subprocess.Popen([sys.executable, "-m", "tespike", "synthesize", "--config", "te", "--height", "8",
                                "--width", "8", "-q"], env=dict(_checkout_env(), TMPDIR=str(temporary)),
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while process.poll() is None and not (glob.glob(str(temporary / "yosys-abc-*"))
                                          or glob.glob(str(temporary / "*" / "yosys-abc-*"))):
        assert time.monotonic() < deadline, "no ABC folder within 2 minutes"
        time.sleep(0.005)
    assert process.poll() is None, "the command ended before its ABC folder was seen"
    os.killpg(process.pid, stop)
    process.communicate(timeout=60)
    for _ in range(100):                                  # (the janitor removes them as the command ends)
        if not os.listdir(temporary):
            break
        time.sleep(0.05)
    assert os.listdir(temporary) == []


def test_a_failed_proof_pool_has_closed_its_wakeup_before_the_error_leaves():
    """A proof that fails in a worker (``prove`` under ``ulimit -f``) ends the pool at once; the
    pool's manager thread has closed its wakeup pipe before the error reaches the command. CPython
    3.11's exit hook (``concurrent.futures.process._python_exit``) writes to that pipe without the
    lock the manager thread closes it under: the command's one line was followed, once in a CI run,
    by "Exception ignored in: <module 'threading'> ... OSError: [Errno 9] Bad file descriptor"."""
    body = ("import concurrent.futures.process as process\n"
            "from tespike.cosim.commands import prove_cmd\n"
            "def failing(task, *settings):\n"
            "    raise OSError(27, 'File too large')\n"
            "prove_cmd.run_task = failing\n"
            "try:\n"
            "    list(prove_cmd._results(['a', 'b', 'c'], 2, ()))\n"
            "except OSError as exc:\n"
            "    print(exc.strerror)\n"
            "print(all(wakeup._closed for wakeup in process._threads_wakeups.values()))\n")
    for _ in range(3):
        done = subprocess.run([sys.executable, "-c", body], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0 and done.stdout.split("\n")[:2] == ["File too large", "True"], done
        assert done.stderr == "", done.stderr
