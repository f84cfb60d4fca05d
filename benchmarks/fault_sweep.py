"""Fault sweep of the ``tespike`` command: truncated inputs, interrupted and starved runs (issue 28, item 6).

A tool, not a test: in a temporary folder it makes one small valid input of every kind the
commands read (configuration JSON, noise JSON, scene I.npy, stimulus E.npy, stream S.npz,
calibration C.npz, reconstruction R.npy, shipped and trained weights .pt, a training
checkpoint, a dataset store's chunk and ``zarr.json`` files, .hdr / .exr frame folders, a
Verilog file), then

* **truncation**: for every (command, input) pair cuts the input at 0 bytes, 1 byte, half,
  all but one byte, and flips the middle byte, runs the command with a timeout and checks
  that it ends cleanly;
* **interruption**: sends SIGINT to the process group (Ctrl-C), SIGTERM to the command
  (``kill``) and SIGKILL to the command (``kill -9``, the out-of-memory killer) of every long
  command at several moments; killed outright it can print nothing, so there a clean ending
  is: nothing on stderr, no process left, no temporary left (its janitor removes them) and
  the output the previous one or a whole new one;
* **starvation** (cases named ``starve ...``): runs every long command once unstarved (what
  it writes, its VmPeak), then with its outputs on a small tmpfs (also its TMPDIR) filled to
  leave part of that room, under RLIMIT_FSIZE, RLIMIT_NOFILE and RLIMIT_AS at several levels.

A clean ending: exit status non-zero, stderr exactly one line without "Traceback" that names
the input (its path as given; a starved run: tespike's line naming the file or resource and
the cause), the output (pre-created where it may exist) untouched and no ``.part``
temporary beside it, and no process of the command's session (or working in its folder)
left. A flipped byte may be harmless where the file stays a valid file of its kind (a
changed pixel value: the command then succeeds, and the table says so), as may a starved
run the limit did not reach. Prints one row per case and a count; exits 1 if any case
misbehaves.

    python3 benchmarks/fault_sweep.py                    # everything, about 40 minutes on 2 cores
    python3 benchmarks/fault_sweep.py --only reconstruct --no-interrupt
    python3 benchmarks/fault_sweep.py --only starve --starve files,memory   # the starvation family, part of it
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MODES = ("empty", "1byte", "half", "less1", "flip")
TIMEOUT = 120
#: A resumed training (a run log cut at its last newline is mended) trains and validates its
#: weights: 130 s on 2 loaded cores, not a hang.
RESUME_TIMEOUT = 300


# ------------------------------------------------------------------ running a command
@dataclass
class Outcome:
    code: int | None
    stderr: str
    stdout: str
    orphans: list[str]
    seconds: float


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _session_processes(sid: int) -> list[str]:
    """Live processes of session ``sid`` (the command's own and every child it started); a zombie
    (exited, waiting for init to reap it) is not one."""
    done = subprocess.run(["ps", "-eo", "pid=,sid=,stat=,args="], capture_output=True, text=True)
    left = []
    for line in done.stdout.splitlines():
        parts = line.split(None, 3)
        if len(parts) >= 3 and parts[1] == str(sid) and not parts[2].startswith("Z"):
            left.append(line.strip()[:120])
    return left


def _working_in(folder: Path) -> list[str]:
    """Live processes whose working folder is ``folder`` or below: what the command started in
    a session of its own (a local Dask cluster) is found there."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            where = os.readlink(entry / "cwd")
            status = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
            args = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if status != "Z" and (where == str(folder) or where.startswith(str(folder) + os.sep)):
            found.append(f"{entry.name} {args}"[:120])
    return found


def _left_behind(sid: int, folder: Path, grace: float = 3.0) -> list[str]:
    """The command's processes still alive ``grace`` seconds after it ended (a worker that ends
    when its pipe closes gets that long): those of its session and any working in ``folder``."""
    end = time.monotonic() + grace
    while True:
        left = sorted(set(_session_processes(sid)) | set(_working_in(folder)))
        if not left or time.monotonic() > end:
            return left
        time.sleep(0.2)


def _default_sigint() -> None:
    """SIGINT as a terminal's command gets it: a sweep started in the background (``&``) has it
    ignored, which its children would inherit (Python then never raises KeyboardInterrupt)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _starting(limits: dict[int, int]):
    """The child's set-up before ``exec``: default SIGINT, then the resource limits ``limits``
    (``resource.RLIMIT_*`` -> soft and hard value). SIGXFSZ is ignored so that a file over
    RLIMIT_FSIZE fails its write with EFBIG (an OSError) rather than killing the process."""
    def start() -> None:
        import resource
        _default_sigint()
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        for which, value in limits.items():
            resource.setrlimit(which, (value, value))
    return start


def _vm_peak(pid: int) -> int:
    """The process's largest address space so far (VmPeak, bytes); 0 once it has ended."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmPeak:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def run_command(argv: list[str], cwd: Path, *, signal_at: float | None = None, signum: int = signal.SIGINT,
                group: bool = True, timeout: float = TIMEOUT, limits: dict[int, int] | None = None,
                watch: list[int] | None = None, env: dict | None = None) -> Outcome:
    """Run ``python3 -m tespike ARGV`` in a session of its own, optionally signalled after ``signal_at`` s,
    under the resource ``limits``; ``watch`` (a list) gets the command's VmPeak appended."""
    start = time.monotonic()
    proc = subprocess.Popen(["nice", "-n", "10", sys.executable, "-m", "tespike", *argv], cwd=cwd,
                            env=dict(_env(), **(env or {})), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, preexec_fn=_starting(limits or {}))
    if watch is not None:                   # polled beside communicate() (which drains the pipes)
        def poll() -> None:
            peak = 0
            while proc.poll() is None:
                peak = max(peak, _vm_peak(proc.pid))
                time.sleep(0.02)
            watch.append(peak)
        watcher = threading.Thread(target=poll, daemon=True)
        watcher.start()
    if signal_at is not None and signal_at < 0:         # mid-output: as soon as a temporary appears
        while proc.poll() is None and not parts_left(cwd) and time.monotonic() - start < timeout:
            time.sleep(0.02)
        if proc.poll() is None:
            (os.killpg if group else os.kill)(proc.pid, signum)
    elif signal_at is not None:
        try:
            proc.wait(signal_at)
        except subprocess.TimeoutExpired:
            (os.killpg if group else os.kill)(proc.pid, signum)
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
        code = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        stdout, stderr = proc.communicate()
        code = None
    if watch is not None:
        watcher.join(5)
    orphans = _left_behind(proc.pid, cwd)
    for line in orphans:                     # never leave them running
        try:
            os.kill(int(line.split()[0]), signal.SIGKILL)
        except (ProcessLookupError, ValueError):
            pass
    return Outcome(code, stderr, stdout, orphans, time.monotonic() - start)


# ------------------------------------------------------------------ the output's state
def state(path: Path) -> dict:
    """Every entry at and under ``path`` with a hash of its bytes ({} when absent)."""
    if not os.path.lexists(path):
        return {}
    if path.is_file():
        return {".": hashlib.sha1(path.read_bytes()).hexdigest()}
    out = {}
    for dirpath, dirnames, filenames in os.walk(path):
        for name in dirnames + filenames:
            full = Path(dirpath, name)
            out[str(full.relative_to(path))] = hashlib.sha1(full.read_bytes()).hexdigest() if full.is_file() else "d"
    return out


def parts_beside(path: Path) -> list[str]:
    folder = path.parent
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".part")) if folder.is_dir() else []


#: Output kinds a case finds made by a previous run (:func:`precreate`).
PRECREATED = ("file", "folder", "frames")


def precreate(path: Path, kind: str) -> None:
    """A previous run's output at ``path``: a file, or a folder with one file (a results folder's
    table, or ``frames``: a folder of view --each, which refuses any file but its frames)."""
    if kind == "file":
        path.write_bytes(b"previous run")
    elif kind in ("folder", "frames"):
        path.mkdir()
        (path / ("table.md" if kind == "folder" else "frame_0000.png")).write_text("previous run")


# ------------------------------------------------------------------ inputs
def tespike(cwd: Path, *argv) -> None:
    done = subprocess.run([sys.executable, "-m", "tespike", *map(str, argv)], cwd=cwd, env=_env(),
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"fault_sweep: making an input failed: tespike {' '.join(map(str, argv))}: {done.stderr}")


def make_inputs(base: Path) -> None:
    """One small valid input of every kind under ``base/valid``."""
    from tespike.golden.config import load_config
    from tespike.recon.learned import WEIGHTS_DIR, weights_name
    from tespike.recon.scenes.hdr_io import write_exr, write_hdr

    v = base / "valid"
    v.mkdir()
    (v / "cfg.json").write_text(json.dumps(load_config("te").to_dict(), indent=1))
    (v / "noise.json").write_text('{"dark_current": "eq12", "dark_level": 2.0, "dsnu": 0.3}')
    tespike(v, "scene", "--name", "default", "--frames", 12, "--height", 16, "--width", 16, "--out", "I.npy", "-q")
    tespike(v, "simulate", "--config", "te", "--scene", "I.npy", "--out", "S.npz", "--seed", 1, "-q")
    tespike(v, "stimulus", "--config", "te", "--scene", "I.npy", "--out", "E.npy", "--seed", 1,
            "--crop", "0,0,4,4", "--readouts", 2, "--quiet")
    tespike(v, "reconstruct", "--stream", "S.npz", "--method", "tfp", "--out", "R.npy", "-q")
    np.save(v / "dark.npy", np.zeros((12, 16, 16), np.float32))
    np.save(v / "flat.npy", np.full((12, 16, 16), 0.03, np.float32))
    for name in ("dark", "flat"):
        tespike(v, "simulate", "--config", "te", "--scene", f"{name}.npy", "--out", f"{name}.npz", "--seed", 2,
                "--noise", "noise.json", "--sensor-seed", 3, "-q")
    tespike(v, "calibrate", "--dark", "dark.npz", "--flat", "flat.npz", "--flat-light", 0.03, "--out", "C.npz",
            "--quiet")
    shutil.copy(WEIGHTS_DIR / weights_name("net", "te"), v / "W.pt")
    tespike(v, "train", "--config", "te", "--steps", 2, "--batch", 1, "--crop", 32, "--workers", 0,
            "--pool", 4, "--validate-every", 1000, "--out", "T.pt", "-q")    # (a small pool: a resume fits TIMEOUT)
    rng = np.random.default_rng(0)
    for kind, writer in (("hdr", write_hdr), ("exr", write_exr)):
        folder = v / "frames" / kind
        folder.mkdir(parents=True)
        for k in range(3):
            writer(folder / f"f{k}.{kind}", rng.uniform(0.05, 2.0, (16, 16, 3)).astype(np.float32))
    tespike(v, "dataset", "--scene", "default", "--frames", 4, "--height", 16, "--width", 16, "--config", "te",
            "--out", "D.zarr", "-q")
    tespike(v, "verilog", "--config", "te", "--height", 2, "--width", 2, "--out", "A.v", "-q")


def copy_inputs(valid: Path, work: Path) -> None:
    for entry in valid.iterdir():
        if entry.is_dir():
            shutil.copytree(entry, work / entry.name, symlinks=True)
        else:
            shutil.copy2(entry, work / entry.name)


def store_members(store: Path) -> dict[str, str]:
    """The dataset store's files the sweep corrupts: root and array zarr.json, one chunk."""
    chunks = sorted(p for p in store.rglob("*") if p.is_file() and "c" in p.relative_to(store).parts[:-1])
    members = {"zarr.json": "zarr.json"}
    arrays = sorted(p for p in store.rglob("zarr.json") if p.parent != store and (p.parent / "c").exists())
    if arrays:
        members["array zarr.json"] = str(arrays[0].relative_to(store))
    if chunks:
        members["chunk"] = str(chunks[0].relative_to(store))
    return members


def corrupt(path: Path, mode: str) -> str:
    """Cut or flip ``path`` in place; returns what was done."""
    data = path.read_bytes()
    n = len(data)
    if mode == "empty":
        path.write_bytes(b"")
    elif mode == "1byte":
        path.write_bytes(data[:1])
    elif mode == "half":
        path.write_bytes(data[: n // 2])
    elif mode == "less1":
        path.write_bytes(data[: n - 1])
    elif mode == "flip":
        middle = n // 2
        path.write_bytes(data[:middle] + bytes([data[middle] ^ 0xFF]) + data[middle + 1:])
    return mode


def still_valid(path: Path) -> bool:
    """Whether a flipped file is still a valid file of its kind (a flip in the data, not the format)."""
    suffix = path.suffix
    try:
        if suffix == ".json":
            json.loads(path.read_text())
            return True
        if suffix == ".npy":
            array = np.load(path)
            return bool(np.isfinite(array).all()) if array.dtype.kind == "f" else True
        if suffix == ".hdr":
            return True                      # a changed pixel (Radiance RLE has no checksum)
        if suffix == ".exr":                 # stored uncompressed where ZIP does not pay: a changed pixel
            from tespike.recon.scenes.hdr_io import read_exr
            return bool(np.isfinite(read_exr(path)).all())
        if suffix == ".v":
            return True                      # a changed character: judged by yosys
    except Exception:
        return False
    return False


# ------------------------------------------------------------------ the cases
@dataclass
class Case:
    """One (command, input) pair: argv with ``{in}`` where the corrupted input goes, ``{out}`` the output."""
    name: str
    source: str                  # path under valid/ of the input (file or folder)
    argv: list[str]
    member: str | None = None    # for a folder input: the file inside it to corrupt
    out: str | None = "out"      # output path name; None: the command writes nothing
    out_kind: str = "file"       # file / folder / frames (view --each's) / none (do not pre-create)
    modes: tuple[str, ...] = MODES
    extra: dict = field(default_factory=dict)
    env: dict = field(default_factory=dict)     # environment of the command, ``{work}`` its folder
    timeout: float = TIMEOUT     # seconds before the case counts as hung (a resumed training validates: longer)


def evaluate_argv(methods: str, *more: str) -> list[str]:
    """A small ``tespike evaluate`` with ``methods``, each option once (one given twice is refused)."""
    return ["evaluate", "--methods", methods, "--repeats", "1", "--ml-count-config", "none", "--progress", "off",
            *more]


EVAL = evaluate_argv("tfp", "--set", "none")


def truncation_cases(valid: Path) -> list[Case]:
    members = store_members(valid / "D.zarr")
    cases = [
        Case("golden config", "cfg.json", ["golden", "--config", "{in}", "--stimulus", "E.npy", "--out", "{out}"],
             out="S.npz"),
        Case("golden stimulus", "E.npy", ["golden", "--config", "te", "--stimulus", "{in}", "--out", "{out}"],
             out="S.npz"),
        Case("simulate config", "cfg.json", ["simulate", "--config", "{in}", "--scene", "I.npy", "--out", "{out}",
                                             "--seed", "1"], out="S.npz"),
        Case("simulate scene", "I.npy", ["simulate", "--config", "te", "--scene", "{in}", "--out", "{out}",
                                         "--seed", "1"], out="S.npz"),
        Case("simulate noise", "noise.json", ["simulate", "--config", "te", "--scene", "I.npy", "--noise", "{in}",
                                              "--out", "{out}", "--seed", "1"], out="S.npz"),
        Case("simulate scene workers", "I.npy", ["simulate", "--config", "te", "--scene", "{in}", "--out", "{out}",
                                                 "--seed", "1", "--workers", "2"], out="S.npz", modes=("half",)),
        Case("stimulus scene", "I.npy", ["stimulus", "--config", "te", "--scene", "{in}", "--out", "{out}",
                                         "--seed", "1", "--readouts", "2"], out="E.npy"),
        Case("rtl-sim stimulus", "E.npy", ["rtl-sim", "--config", "te", "--stimulus", "{in}", "--out", "{out}"],
             out="S.npz"),
        Case("verilog config", "cfg.json", ["verilog", "--config", "{in}", "--height", "2", "--width", "2",
                                            "--out", "{out}"], out="A.v"),
        Case("synthesize verilog", "A.v", ["synthesize", "--verilog", "{in}"], out=None, out_kind="none"),
        Case("calibrate dark", "dark.npz", ["calibrate", "--dark", "{in}", "--flat", "flat.npz", "--flat-light",
                                            "0.03", "--out", "{out}"], out="C.npz"),
        Case("calibrate flat", "flat.npz", ["calibrate", "--dark", "dark.npz", "--flat", "{in}", "--flat-light",
                                            "0.03", "--out", "{out}"], out="C.npz"),
        Case("reconstruct stream", "S.npz", ["reconstruct", "--stream", "{in}", "--method", "tfp", "--out", "{out}"],
             out="R.npy"),
        Case("reconstruct shipped weights", "W.pt", ["reconstruct", "--stream", "S.npz", "--method", "net",
                                                     "--weights", "{in}", "--out", "{out}"], out="R.npy"),
        Case("reconstruct trained weights", "T.pt", ["reconstruct", "--stream", "S.npz", "--method", "net",
                                                     "--weights", "{in}", "--out", "{out}"], out="R.npy"),
        Case("reconstruct calibration", "C.npz", ["reconstruct", "--stream", "dark.npz", "--method", "tfp",
                                                  "--calibration", "{in}", "--out", "{out}"], out="R.npy"),
        Case("score reference", "I.npy", ["score", "--reference", "{in}", "--estimate", "R.npy",
                                          "--metrics", "psnr_mu"], out=None, out_kind="none"),
        Case("score estimate", "R.npy", ["score", "--reference", "I.npy", "--estimate", "{in}",
                                         "--metrics", "psnr_mu"], out=None, out_kind="none"),
        Case("view scene", "I.npy", ["view", "--input", "{in}", "--out", "{out}"], out="v.png"),
        Case("view stream", "S.npz", ["view", "--input", "{in}", "--out", "{out}"], out="v.png"),
        Case("view stimulus", "E.npy", ["view", "--input", "{in}", "--config", "te", "--out", "{out}"], out="v.png"),
        Case("view each", "R.npy", ["view", "--input", "{in}", "--each", "--out", "{out}"], out="vdir",
             out_kind="frames"),
        Case("scene hdr", "frames/hdr", ["scene", "--folder", "{in}", "--out", "{out}"], member="f1.hdr",
             out="I2.npy"),
        Case("scene exr", "frames/exr", ["scene", "--folder", "{in}", "--out", "{out}"], member="f1.exr",
             out="I2.npy"),
        Case("evaluate scene", "I.npy", EVAL + ["--scene", "{in}", "--out", "{out}", "--force"], out="ev",
             out_kind="folder"),
        Case("evaluate folder", "frames/hdr", EVAL + ["--folder", "{in}", "--out", "{out}",
                                                      "--force"], member="f1.hdr", out="ev", out_kind="folder"),
        Case("evaluate weights", "T.pt", evaluate_argv("tfp,net", "--set", "none", "--scene", "I.npy", "--weights", "{in}",
                                                    "--out", "{out}", "--force"), out="ev", out_kind="folder"),
        Case("evaluate sensor noise", "noise.json", EVAL + ["--scene", "I.npy", "--sensor-noise", "{in}",
                                                            "--out", "{out}", "--force"], out="ev",
             out_kind="folder"),
        Case("train config", "cfg.json", ["train", "--config", "{in}", "--steps", "2", "--batch", "1", "--crop",
                                          "32", "--workers", "0", "--out", "{out}"], out="T2.pt", out_kind="none"),
        Case("train init", "T.pt", ["train", "--config", "te", "--init", "{in}", "--steps", "2", "--batch", "1",
                                    "--crop", "32", "--workers", "0", "--out", "{out}"], out="T2.pt",
             out_kind="none"),
        Case("train hdr", "frames/hdr", ["train", "--config", "te", "--hdr", "{in}", "--steps", "2", "--batch", "1",
                                         "--crop", "16", "--workers", "0", "--out", "{out}"], member="f1.hdr",
             out="T2.pt", out_kind="none"),
        Case("train resume", "T.run", ["train", "--config", "te", "--steps", "3", "--batch", "1", "--crop", "32",
                                          "--workers", "0", "--pool", "4", "--resume", "--out", "{out}"],
             member="checkpoint.pt", out="T.pt", out_kind="resume", timeout=RESUME_TIMEOUT),
        *[Case(f"train resume {member}", "T.run", ["train", "--config", "te", "--steps", "3", "--batch", "1",
                                                   "--crop", "32", "--workers", "0", "--pool", "4", "--resume",
                                                   "--out", "{out}"],
               member=member, out="T.pt", out_kind="resume", timeout=RESUME_TIMEOUT)
          for member in ("log.csv", "validation.csv", "best.pt")],
        Case("dataset resume zarr.json", "D.zarr", ["dataset", "--scene", "default", "--frames", "4", "--height",
                                                    "16", "--width", "16", "--config", "te", "--out", "{in}"],
             member="zarr.json", out=None, out_kind="none"),
        *[Case(f"dataset resume {label}", "D.zarr", ["dataset", "--scene", "default", "--frames", "4", "--height",
                                                     "16", "--width", "16", "--config", "te", "--out", "{in}"],
               member=member, out=None, out_kind="none")
          for label, member in members.items() if label in ("chunk", "array zarr.json")],
        Case("dataset hdr", "frames", ["dataset", "--hdr", "{in}", "--frames", "3", "--config", "te",
                                       "--out", "{out}"], member="hdr/f1.hdr", out="D2.zarr", out_kind="none"),
        Case("dataset config", "cfg.json", ["dataset", "--scene", "default", "--frames", "4", "--height", "16",
                                            "--width", "16", "--config", "{in}", "--out", "{out}"], out="D2.zarr",
             out_kind="none"),
    ]
    for label, member in members.items():
        cases.append(Case(f"evaluate store {label}", "D.zarr", ["evaluate", "--store", "{in}", "--methods", "tfp",
                                                                "--progress", "off", "--out", "{out}", "--force"],
                          member=member, out="ev", out_kind="folder"))
    return cases


def run_truncation(case: Case, mode: str, base: Path) -> tuple[bool, str]:
    """Run one corrupted case in a fresh copy of the inputs; (passed, what happened)."""
    work = Path(tempfile.mkdtemp(dir=base, prefix="case."))
    copy_inputs(base / "valid", work)
    given = case.source
    target = work / given / case.member if case.member else work / given
    last_byte = target.read_bytes()[-1:]
    corrupt(target, mode)
    out = work / case.out if case.out else None
    if out is not None and case.out_kind in PRECREATED:
        if out.exists():
            shutil.rmtree(out) if out.is_dir() else out.unlink()
        precreate(out, case.out_kind)
    elif out is not None and case.out_kind == "none" and os.path.lexists(out):
        shutil.rmtree(out) if out.is_dir() else out.unlink()
    before = state(out) if out is not None else {}
    run_before = state(work / "T.run") if case.out_kind == "resume" else {}
    argv = [a.replace("{in}", given).replace("{out}", case.out or "") for a in case.argv]
    outcome = run_command(argv, work, timeout=case.timeout)
    try:
        blank_cut = mode == "less1" and last_byte.isspace()
        return judge(case, mode, outcome, work, target, given, out, before, run_before, blank_cut)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def names(line: str, given: str) -> bool:
    """Whether ``line`` names the path ``given`` as the user typed it (or a file inside it)."""
    return re.search(r"(^|[\s'\"(])" + re.escape(given) + r"([\s'\":/),]|$)", line) is not None


def judge(case, mode, outcome, work, target, given, out, before, run_before, blank_cut) -> tuple[bool, str]:
    lines = outcome.stderr.strip().splitlines()
    first = lines[0] if lines else ""
    if outcome.code is None:
        return False, f"timed out after {case.timeout:g} s"
    if outcome.orphans:
        return False, f"left {len(outcome.orphans)} process(es): {outcome.orphans[0]}"
    if outcome.code == 0:
        rebuilt = [line for line in outcome.stdout.splitlines() if line.endswith(": rebuilding what is damaged")]
        if rebuilt:                                             # a resumed store's damaged chunk
            return True, "rebuilt: " + rebuilt[0][:160]
        if mode == "flip" and still_valid(target):
            return True, "harmless: the flipped byte leaves a valid file (a changed value); run succeeded"
        if blank_cut:
            return True, "harmless: the byte cut is the text's final blank; run succeeded"
        return False, f"exit 0 on a corrupted input{': ' + first if first else ''}"
    if "Traceback" in outcome.stderr:
        return False, f"traceback: {lines[-1][:160] if lines else ''}"
    if len(lines) != 1:
        return False, f"{len(lines)} lines on stderr: {first[:100]} ... {lines[-1][:100] if lines else ''}"
    if not names(first, given):
        return False, f"does not name {given!r} as given: {first[:200]}"
    if out is not None and case.out_kind in PRECREATED and state(out) != before:
        return False, f"output {case.out} changed: {first[:160]}"
    if out is not None and case.out_kind == "none" and os.path.lexists(out) and "resumes it" not in first:
        return False, f"output {case.out} left behind: {first[:160]}"     # a store kept to resume says so
    if case.out_kind == "resume" and state(work / "T.pt") != before:
        return False, f"weights {case.out} changed: {first[:160]}"
    if out is not None and parts_beside(out):
        return False, f"temporaries left: {parts_beside(out)}"
    return True, first[:200]


# ------------------------------------------------------------------ interruptions
def interrupt_cases() -> list[Case]:
    """Long commands, each run until a signal; ``out`` is pre-created where the command may replace it."""
    return [
        Case("simulate --workers 2", "", ["simulate", "--config", "te", "--scene", "big.npy", "--out", "S.npz",
                                          "--seed", "1", "--workers", "2", "--progress", "off"], out="S.npz"),
        Case("evaluate", "", evaluate_argv("tfp,tfi", "--set", "default", "--frames", "12", "--height", "32", "--width",
                                         "32", "--out", "ev", "--force"), out="ev", out_kind="folder"),
        Case("evaluate --store --workers 2", "", ["evaluate", "--store", "D.zarr", "--methods", "tfp,tfi",
                                                  "--progress", "off", "--workers", "2",
                                                  "--out", "ev", "--force"], out="ev", out_kind="folder"),
        Case("train", "", ["train", "--config", "te", "--steps", "40", "--batch", "1", "--crop", "32",
                           "--workers", "1", "--progress", "off", "--out", "T2.pt"], out="T2.pt", out_kind="none"),
        Case("dataset --workers 2", "", ["dataset", "--scene", "default", "--frames", "12", "--height", "32",
                                         "--width", "32", "--config", "te", "--config", "ml", "--workers", "2",
                                         "--progress", "off", "--out", "D2.zarr"], out="D2.zarr", out_kind="none"),
        Case("reconstruct net", "", ["reconstruct", "--stream", "S.npz", "--method", "net", "--out", "R.npy",
                                     "--progress", "off"], out="R.npy"),
        Case("rtl-sim --vcd", "", ["rtl-sim", "--config", "te", "--stimulus", "E.npy", "--out", "S2.npz",
                                   "--vcd", "W.vcd", "--progress", "off"], out="S2.npz"),
        Case("calibrate", "", ["calibrate", "--dark", "dark.npz", "--flat", "flat.npz", "--flat-light", "0.03",
                               "--out", "C.npz"], out="C.npz"),
        Case("demo", "", ["demo", "--out", "demo", "--frames", "10", "--height", "32", "--width", "32",
                          "--crop", "11", "--repeats", "1", "--sensors", "te", "--no-hw-cost", "--quiet"],
             out="demo", out_kind="folder"),
    ] + [  # an empty build cache each run: the simulator built (make, the compilers), then run
        Case(f"cocotb {simulator}", "", ["cocotb", "--config", "te", "--height", "8", "--width", "8",
                                         "--readouts", "40", "--simulator", simulator, "--work-dir", "cw"],
             out="nothing", out_kind="none", env={"TESPIKE_CACHE": "{work}/cache"})
        for simulator in ("icarus", "verilator")
    ]


def run_interrupt(case: Case, at: float, signum: int, base: Path) -> tuple[bool, str]:
    work = Path(tempfile.mkdtemp(dir=base, prefix="int."))
    copy_inputs(base / "valid", work)
    out = work / case.out
    if case.out_kind in PRECREATED:
        if out.exists():
            shutil.rmtree(out) if out.is_dir() else out.unlink()
        precreate(out, case.out_kind)
    before = state(out)
    outcome = run_command(case.argv, work, signal_at=at, signum=signum, group=signum == signal.SIGINT,
                          env={k: v.replace("{work}", str(work)) for k, v in case.env.items()})
    try:
        if signum == signal.SIGKILL:
            return judge_kill(case, outcome, work, out, before)
        lines = outcome.stderr.strip().splitlines()
        first = lines[0] if lines else ""
        if outcome.code is None:
            return False, "timed out"
        if outcome.orphans:
            return False, f"left {len(outcome.orphans)} process(es): {outcome.orphans[0]}"
        if outcome.code == 0:
            return True, f"finished before the signal ({outcome.seconds:.1f} s)"
        if outcome.code == -signum and not lines and not parts_left(work):
            if state(out) == before:
                return True, (f"killed before its handlers were set or after they were restored "
                              f"(exit {outcome.code}); output untouched")
            if "wrote" in outcome.stdout:
                return True, f"killed after it finished and wrote its output whole (exit {outcome.code})"
        if "Traceback" in outcome.stderr:
            return False, f"traceback ({len(lines)} lines): {lines[-1][:140] if lines else ''}"
        if len(lines) != 1:
            return False, (f"exit {outcome.code}, {len(lines)} lines on stderr: {first[:100]} ... "
                           f"{lines[-1][:100] if lines else ''}")
        if case.out_kind in PRECREATED and state(out) != before and "whole" not in first:
            return False, f"output {case.out} changed: {first[:140]}"
        if case.out_kind == "none" and os.path.lexists(out) and not case.name.startswith(("train", "dataset")):
            return False, f"output {case.out} left: {first[:140]}"
        if case.name.startswith("train") and os.path.lexists(out) and "whole" not in first:
            return False, f"weights {case.out} written by an interrupted run: {first[:140]}"
        if case.name.startswith("train") and os.path.lexists(work / "T2.run") \
                and not any(os.scandir(work / "T2.run")):
            return False, f"empty run folder left: {first[:140]}"
        left = parts_left(work)
        if left:
            return False, f"temporaries left: {left[:3]}"
        return True, first[:160]
    finally:
        shutil.rmtree(work, ignore_errors=True)


def judge_kill(case: Case, outcome: Outcome, work: Path, out: Path, before: dict) -> tuple[bool, str]:
    """A command killed outright (SIGKILL to it alone: no handler runs, so it prints nothing):
    nothing on stderr (a worker's traceback or a tool's notice would show), no process left, no
    temporary left once its janitor has had a moment, and its output the previous one or a
    whole new one (it was moved into place before the kill)."""
    if outcome.code is None:
        return False, "timed out"
    if outcome.code == 0:
        return True, f"finished before the signal ({outcome.seconds:.1f} s)"
    if outcome.orphans:
        return False, f"left {len(outcome.orphans)} process(es): {outcome.orphans[0]}"
    if outcome.stderr.strip():
        lines = outcome.stderr.strip().splitlines()
        return False, f"{len(lines)} lines on stderr after the kill: {lines[-1][:140]}"
    end = time.monotonic() + 2.0                       # the janitor removes them within milliseconds
    while parts_left(work) and time.monotonic() < end:
        time.sleep(0.05)
    left = parts_left(work)
    if left:
        return False, f"temporaries left: {left[:3]}"
    if state(out) == before:
        return True, f"killed (exit {outcome.code}); output untouched, nothing left"
    if whole_output(out):
        return True, f"killed (exit {outcome.code}) after its output was in place whole"
    return False, f"output {case.out} changed and not whole"


def whole_output(path: Path) -> bool:
    """Whether ``path`` is a complete output: a zip (S.npz, C.npz, weights) whose members check, an
    array that loads, a results folder without temporaries, another file that is not empty."""
    import zipfile
    if path.is_dir():
        return any(path.iterdir()) and not list(path.rglob("*.part"))
    try:
        if path.suffix in (".npz", ".pt"):
            with zipfile.ZipFile(path) as archive:
                return archive.testzip() is None
        if path.suffix == ".npy":
            np.load(path, mmap_mode="r")
            return True
        return path.stat().st_size > 0
    except Exception:
        return False


def parts_left(work: Path) -> list[str]:
    """``.part`` temporaries anywhere under ``work``."""
    return [str(p.relative_to(work)) for p in work.rglob("*.part")]


def make_long_inputs(valid: Path) -> None:
    """A scene large enough that ``simulate --workers 2`` takes a few seconds."""
    tespike(valid, "scene", "--name", "default", "--frames", 36, "--height", 128, "--width", 256,
            "--out", "big.npy", "-q")


# ------------------------------------------------------------------ starvation
#: What a long command is starved of: its output's disk filling up (a small tmpfs, also the
#: TMPDIR), a file-size limit (RLIMIT_FSIZE: EFBIG), few file handles (RLIMIT_NOFILE: EMFILE)
#: and little memory (RLIMIT_AS: MemoryError, failed allocations).
STARVE_KINDS = ("disk", "fsize", "files", "memory")
#: Free room left on the output's disk, as a fraction of what the command writes there.
DISK_ROOM = (0.0, 0.3, 0.7, 0.95)
#: RLIMIT_FSIZE as a fraction of the command's largest output file.
FSIZE_ROOM = (0.0, 0.5)
#: RLIMIT_NOFILE values: Python and numpy start with 12, a Dask cluster needs many more.
FILE_HANDLES = (12, 20, 32, 64)
#: RLIMIT_AS as a fraction of the command's VmPeak in an unlimited run (the interpreter and its
#: imports take the first part: low values starve the start, high ones the work's last allocations).
MEMORY_ROOM = (0.3, 0.5, 0.7, 0.85, 0.95)
#: What a starved command's line must say, per kind.
STARVE_CAUSE = {"disk": r"No space left on device|disk is full|is free on its file system",
                "fsize": r"File too large|too large",
                "files": r"[Tt]oo many open files|open files|file handles",
                "memory": r"out of memory|[Mm]emory"}
FULL = "full"            # the starved folder under the case's work folder: every output goes there


def starve_cases() -> list[Case]:
    """Long commands writing under ``full/`` (``out``: the output there, pre-created where it may exist)."""
    f = FULL
    return [
        Case("starve simulate --workers 2", "", ["simulate", "--config", "te", "--scene", "big.npy", "--out",
                                                 f"{f}/S.npz", "--seed", "1", "--workers", "2"], out=f"{f}/S.npz"),
        Case("starve stimulus", "", ["stimulus", "--config", "te", "--scene", "I.npy", "--out", f"{f}/E.npy",
                                     "--seed", "1", "--readouts", "4"], out=f"{f}/E.npy"),
        Case("starve evaluate", "", evaluate_argv("tfp,tfi", "--set", "default", "--frames", "12",
                                                "--height", "32", "--width", "32", "--out", f"{f}/ev", "--force"),
             out=f"{f}/ev", out_kind="folder"),
        Case("starve evaluate --store --workers 2", "", ["evaluate", "--store", "D.zarr", "--methods", "tfp,tfi",
                                                         "--progress", "off", "--workers", "2", "--out", f"{f}/ev",
                                                         "--force"], out=f"{f}/ev", out_kind="folder"),
        Case("starve train", "", ["train", "--config", "te", "--steps", "2", "--batch", "1", "--crop", "32",
                                  "--workers", "1", "--pool", "2", "--validate-every", "0", "--progress", "off",
                                  "--out", f"{f}/T2.pt"],
             out=f"{f}/T2.pt", out_kind="none"),
        Case("starve dataset --workers 2", "", ["dataset", "--scene", "default", "--frames", "12", "--height", "32",
                                                "--width", "32", "--config", "te", "--config", "ml", "--workers",
                                                "2", "--progress", "off", "--out", f"{f}/D2.zarr"],
             out=f"{f}/D2.zarr", out_kind="none"),
        Case("starve reconstruct net", "", ["reconstruct", "--stream", "S.npz", "--method", "net", "--out",
                                            f"{f}/R.npy", "--progress", "off"], out=f"{f}/R.npy"),
        Case("starve rtl-sim --vcd", "", ["rtl-sim", "--config", "te", "--stimulus", "E.npy", "--out",
                                          f"{f}/S2.npz", "--vcd", f"{f}/W.vcd", "--progress", "off"],
             out=f"{f}/S2.npz"),
        Case("starve calibrate", "", ["calibrate", "--dark", "dark.npz", "--flat", "flat.npz", "--flat-light",
                                      "0.03", "--out", f"{f}/C.npz"], out=f"{f}/C.npz"),
        Case("starve demo", "", ["demo", "--out", f"{f}/demo", "--frames", "10", "--height", "32", "--width",
                                 "32", "--crop", "11", "--repeats", "1", "--sensors", "te", "--no-hw-cost",
                                 "--quiet"], out=f"{f}/demo", out_kind="folder"),
    ]


@dataclass
class Appetite:
    """What a command takes when nothing is starved: bytes under ``full/``, its largest file, VmPeak."""
    written: int
    largest: int
    vm_peak: int
    seconds: float


def sizes_under(folder: Path) -> list[int]:
    return [p.stat().st_size for p in folder.rglob("*") if p.is_file() and not p.is_symlink()]


def measure(case: Case, base: Path) -> Appetite | str:
    """Run ``case`` unstarved; its appetite, or why it could not be measured."""
    work = Path(tempfile.mkdtemp(dir=base, prefix="measure."))
    try:
        copy_inputs(base / "valid", work)
        (work / FULL).mkdir()
        peaks: list[int] = []
        outcome = run_command(case.argv, work, watch=peaks)
        if outcome.code != 0:
            return f"the unstarved run failed (exit {outcome.code}): {outcome.stderr.strip()[-300:]}"
        sizes = sizes_under(work / FULL)
        return Appetite(sum(sizes), max(sizes, default=0), max(peaks, default=0), outcome.seconds)
    finally:
        shutil.rmtree(work, ignore_errors=True)


@contextlib.contextmanager
def tmpfs(folder: Path, size: int):
    """A tmpfs of ``size`` bytes mounted at ``folder`` (None where this system does not allow it)."""
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={max(size, 1 << 16)}", "tmpfs", str(folder)],
                          capture_output=True)
    if done.returncode != 0:
        yield None
        return
    try:
        yield folder
    finally:
        if subprocess.run(["umount", str(folder)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def fill(folder: Path, leave: int) -> None:
    """Fill ``folder``'s file system so that about ``leave`` bytes stay free."""
    info = os.statvfs(folder)
    extra = info.f_bavail * info.f_frsize - leave
    block = b"\0" * (1 << 20)
    with open(folder / ".filler", "wb") as out:
        while extra > 0:
            extra -= out.write(block[:min(extra, len(block))])


def starve_levels(kinds: list[str], appetite: Appetite) -> list[tuple[str, str, dict[int, int], int | None]]:
    """(kind, label, resource limits, free bytes on a full disk or None) for every starved run of a command."""
    import resource
    levels = []
    if "disk" in kinds:
        for room in DISK_ROOM:
            free = int(room * appetite.written)
            levels.append(("disk", f"disk@{room:g}", {}, free))
    if "fsize" in kinds:
        for room in FSIZE_ROOM:
            levels.append(("fsize", f"fsize@{room:g}", {resource.RLIMIT_FSIZE: int(room * appetite.largest)}, None))
    if "files" in kinds:
        for handles in FILE_HANDLES:
            levels.append(("files", f"nofile={handles}", {resource.RLIMIT_NOFILE: handles}, None))
    if "memory" in kinds:
        for room in MEMORY_ROOM:
            levels.append(("memory", f"as@{room:g}", {resource.RLIMIT_AS: int(room * appetite.vm_peak)}, None))
    return levels


def run_starved(case: Case, kind: str, limits: dict[int, int], free: int | None, appetite: Appetite,
                base: Path) -> tuple[bool, str]:
    """Run ``case`` starved of ``kind``; (passed, what happened)."""
    work = Path(tempfile.mkdtemp(dir=base, prefix="starve."))
    full = work / FULL
    full.mkdir()
    copy_inputs(base / "valid", work)
    size = 2 * appetite.written + (8 << 20) if free is not None else 0
    try:
        with (tmpfs(full, size) if free is not None else contextlib.nullcontext(full)) as mount:
            if mount is None:
                return True, "skipped: cannot mount a tmpfs here"
            out = work / case.out
            if case.out_kind in PRECREATED:
                precreate(out, case.out_kind)
            before = state(out)
            env = {}
            if free is not None:
                fill(full, free)
                env["TMPDIR"] = str(full)          # a full disk is full for the command's temporaries too
            outcome = run_command(case.argv, work, limits=limits, env=env)
            (full / ".filler").unlink(missing_ok=True)
            return judge_starved(case, kind, outcome, work, out, before)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def judge_starved(case: Case, kind: str, outcome: Outcome, work: Path, out: Path, before: dict) -> tuple[bool, str]:
    lines = outcome.stderr.strip().splitlines()
    first = lines[0] if lines else ""
    left = parts_left(work)
    if outcome.code is None:
        return False, f"timed out after {case.timeout:g} s"
    if outcome.orphans:
        return False, f"left {len(outcome.orphans)} process(es): {outcome.orphans[0]}"
    if left:
        return False, f"temporaries left: {left[:3]}"
    if outcome.code == 0:
        return True, f"finished within the limit ({outcome.seconds:.1f} s)"
    if outcome.code < 0:
        return False, (f"killed by {signal.Signals(-outcome.code).name}: "
                       f"{lines[-1][:140] if lines else 'nothing on stderr'}")
    if "Traceback" in outcome.stderr:
        return False, f"traceback ({len(lines)} lines): {lines[-1][:140] if lines else ''}"
    if len(lines) != 1:
        return False, f"exit {outcome.code}, {len(lines)} lines on stderr: {first[:100]} ... {lines[-1][:100]}"
    if not first.startswith("tespike"):
        return False, f"a line that is not tespike's: {first[:160]}"      # e.g. OpenBLAS's own, exiting from C
    if not re.search(STARVE_CAUSE[kind], first):
        return False, f"does not say the cause ({kind}): {first[:160]}"
    if kind in ("disk", "fsize") and "'" not in first:
        return False, f"names no file: {first[:160]}"
    if case.out_kind in PRECREATED and state(out) != before and "whole" not in first:
        return False, f"output {case.out} changed: {first[:140]}"
    if case.out_kind == "none" and os.path.lexists(out) and "whole" not in first and "resumes" not in first:
        return False, f"output {case.out} written by a failed run: {first[:140]}"     # (a resumable store says so)
    run_folder = out.with_suffix(".run")
    if case.name.startswith("starve train") and os.path.lexists(run_folder) and not any(os.scandir(run_folder)):
        return False, f"empty run folder left: {first[:140]}"
    return True, first[:200]


# ------------------------------------------------------------------ main
def print_summary(rows: list[tuple[str, str, bool, str]]) -> None:
    """Passed / run per case and family (the label before its ``@`` or ``=``: a truncation mode,
    SIGINT / SIGTERM, disk / fsize / nofile / as)."""
    families: dict[str, None] = {}
    table: dict[str, dict[str, list[int]]] = {}
    for name, label, ok, _ in rows:
        family = re.split("[@=]", label)[0]
        families.setdefault(family)
        cell = table.setdefault(name, {}).setdefault(family, [0, 0])
        cell[0] += ok
        cell[1] += 1
    width = max((len(name) for name in table), default=4) + 2
    print("\n" + "case".ljust(width) + "".join(f"{family:>10}" for family in families))
    for name, cells in table.items():
        print(name.ljust(width) + "".join(f"{'%d/%d' % tuple(cells[f]) if f in cells else '':>10}"
                                          for f in families))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", help="run only the cases whose name contains this text")
    parser.add_argument("--no-truncate", action="store_true", help="skip the truncation sweep")
    parser.add_argument("--no-interrupt", action="store_true", help="skip the interruption sweep")
    parser.add_argument("--no-starve", action="store_true", help="skip the starvation sweep")
    parser.add_argument("--starve", default=",".join(STARVE_KINDS),
                        help=f"what long commands are starved of (default {','.join(STARVE_KINDS)})")
    parser.add_argument("--moments", default="0.3,1,3,8,part",
                        help="seconds after start to signal, 'part': as soon as an output's temporary appears "
                             "(default 0.3,1,3,8,part)")
    parser.add_argument("--modes", default=",".join(MODES), help=f"truncations (default {','.join(MODES)})")
    parser.add_argument("--inputs", metavar="DIR",
                        help="keep the valid inputs in DIR/valid and reuse them on the next run (default: a "
                             "temporary folder, removed)")
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(143))     # unmount and clean up on the way out
    base = Path(args.inputs) if args.inputs else Path(tempfile.mkdtemp(prefix="fault_sweep."))
    rows: list[tuple[str, str, bool, str]] = []
    try:
        if not (base / "valid" / "done").exists():
            shutil.rmtree(base / "valid", ignore_errors=True)
            base.mkdir(parents=True, exist_ok=True)
            make_inputs(base)
            (base / "valid" / "done").write_text("")
        if not args.no_truncate:
            modes = args.modes.split(",")
            for case in truncation_cases(base / "valid"):
                if args.only and args.only not in case.name:
                    continue
                for mode in case.modes:
                    if mode not in modes:
                        continue
                    ok, what = run_truncation(case, mode, base)
                    rows.append((case.name, mode, ok, what))
                    print(f"{'ok  ' if ok else 'FAIL'} {case.name:32} {mode:6} {what}", flush=True)
        if not args.no_interrupt:
            if not (base / "valid" / "big.npy").exists():
                make_long_inputs(base / "valid")
            moments = [-1.0 if m == "part" else float(m) for m in args.moments.split(",")]
            for case in interrupt_cases():
                if args.only and args.only not in case.name:
                    continue
                for at in moments:
                    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
                        ok, what = run_interrupt(case, at, signum, base)
                        label = f"{signal.Signals(signum).name}@{'part' if at < 0 else f'{at:g}s'}"
                        rows.append((case.name, label, ok, what))
                        print(f"{'ok  ' if ok else 'FAIL'} {case.name:32} {label:12} {what}", flush=True)
        if not args.no_starve:
            if not (base / "valid" / "big.npy").exists():
                make_long_inputs(base / "valid")
            kinds = args.starve.split(",")
            for case in starve_cases():
                if args.only and args.only not in case.name:
                    continue
                appetite = measure(case, base)
                if isinstance(appetite, str):
                    rows.append((case.name, "unstarved", False, appetite))
                    print(f"FAIL {case.name:32} {'unstarved':12} {appetite}", flush=True)
                    continue
                print(f"     {case.name:32} {'unstarved':12} writes {appetite.written} B (largest file "
                      f"{appetite.largest} B), VmPeak {appetite.vm_peak >> 20} MiB, {appetite.seconds:.1f} s",
                      flush=True)
                for kind, label, limits, free in starve_levels(kinds, appetite):
                    ok, what = run_starved(case, kind, limits, free, appetite, base)
                    rows.append((case.name, label, ok, what))
                    print(f"{'ok  ' if ok else 'FAIL'} {case.name:32} {label:12} {what}", flush=True)
    finally:
        if not args.inputs:
            shutil.rmtree(base, ignore_errors=True)
    failed = [r for r in rows if not r[2]]
    print_summary(rows)
    print(f"\n{len(rows)} cases: {len(rows) - len(failed)} passed, {len(failed)} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
