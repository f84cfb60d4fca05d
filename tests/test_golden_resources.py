"""tespike.golden.resources: the allocator tuning the fast simulator asks for."""

import platform
import subprocess
import sys

import pytest


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's mallopt only")
def test_keep_freed_memory_applies_once_on_glibc():
    # a fresh process: the setting is process-wide
    code = ("from tespike.golden.resources import keep_freed_memory as k\n"
            "import numpy as np\n"
            "assert k() is True and k() is True\n"
            "a = np.ones(1 << 22); del a\n"
            "print('ok')")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr
