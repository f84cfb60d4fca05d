"""Shared fixtures and configurations for the test suite."""

import numpy as np
import pytest


@pytest.fixture
def one_torch_thread():
    """Tiny tensors: one torch thread (two spin against each other on a busy machine); restored after."""
    import torch
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def empty_weights_dir(tmp_path, monkeypatch):
    """An empty folder as ``tespike.recon.learned.WEIGHTS_DIR``: no learned method has weights,
    whatever the checkout ships; a test may save its own there."""
    import tespike.recon.learned
    from tespike import recon
    folder = tmp_path / "weights"
    folder.mkdir()
    monkeypatch.setattr(recon.learned, "WEIGHTS_DIR", folder)
    return folder


@pytest.fixture(autouse=True)
def sigpipe_left_as_it_was():
    """No test may change how this process meets a closed pipe: with SIGPIPE at the system's
    default (what importing vcdvcd itself does), a later write to a pool worker's pipe killed the
    whole suite without a line. Put back, and the test that changed it fails."""
    import signal
    before = signal.getsignal(signal.SIGPIPE)
    yield
    after = signal.getsignal(signal.SIGPIPE)
    if after != before:
        signal.signal(signal.SIGPIPE, before)
        pytest.fail(f"the test changed SIGPIPE's disposition from {before!r} to {after!r}")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def _full_size_hdri():
    """The full-size CC0 panoramas, for the tests that check the shipped copies against them:
    ``$TESPIKE_HDRI_DIR``, else a ``shared/data/hdri`` folder beside the checkout (or beside the
    folder of its worktrees). The product itself never looks there."""
    import os
    from pathlib import Path
    if os.environ.get("TESPIKE_HDRI_DIR"):
        return Path(os.environ["TESPIKE_HDRI_DIR"])
    root = Path(__file__).resolve().parent.parent
    for base in (root.parent, root.parent.parent):
        if (base / "shared" / "data" / "hdri").is_dir():
            return base / "shared" / "data" / "hdri"
    return root / "no-full-size-hdri"


FULL_SIZE_HDRI = _full_size_hdri()
