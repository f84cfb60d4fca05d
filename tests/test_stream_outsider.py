"""The streaming top against an outsider's reference written from SPEC alone (tests/stream_outsider.py):
non-preset configurations, the smallest legal lane count, non-divisors of H W and N > H W."""
import shutil

import pytest

from tests.stream_outsider import CASES, check

pytestmark = pytest.mark.skipif(shutil.which("iverilog") is None, reason="needs iverilog")


@pytest.mark.parametrize("case", [0, 1, 2, 3, 6, 8, 12, 13, 15], ids=lambda i: "{}-{}x{}-N{}".format(
    CASES[i][0]["mode"] + ("-" + CASES[i][0]["ml_readout"] if CASES[i][0]["mode"] == "ml" else ""), *CASES[i][1:4]))
def test_every_beat_equals_the_outsider_reference(tmp_path, case):
    c, H, W, N, K = CASES[case]
    log = []
    assert check(c, H, W, N, K, 7 + case, log, work=tmp_path) is None
