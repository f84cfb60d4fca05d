"""Run the ``tespike`` command of *this* checkout in a subprocess, as a user would."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _checkout_env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def run_tespike(*args, timeout=600, env=None) -> subprocess.CompletedProcess:
    """``tespike args`` in a fresh interpreter of this checkout; ``env``: variables to set besides."""
    return subprocess.run([sys.executable, "-m", "tespike", *map(str, args)], capture_output=True,
                          text=True, env={**_checkout_env(), **(env or {})}, timeout=timeout)


def run_python(code: str, timeout=600) -> subprocess.CompletedProcess:
    """``python -c code`` in a fresh interpreter that imports this checkout's tespike."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                          env=_checkout_env(), timeout=timeout)


def assert_refused(result: subprocess.CompletedProcess, *words: str) -> None:
    """Non-zero exit, one line on stderr naming the problem, no traceback."""
    assert result.returncode != 0, result
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], (word, lines[0])
