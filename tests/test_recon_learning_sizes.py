"""The sizes every learned method shares (recon/learning/sizes.py, recon/baselines/common.py): the presets, the
fields and checks of the fold, the pyramid and the mu-law, and the shipped weights' sizes read back by name."""

import dataclasses

import pytest

from tespike.golden.errors import InputError
from tespike.recon.baselines.common import BaselineSizes
from tespike.recon.learned import LEARNED, WEIGHTS_DIR, method_classes
from tespike.recon.learning.sizes import SIZE_PRESETS, PyramidSizes
from tespike.recon.learning.weights import read_weights
from tespike.recon.mulaw import MU

#: A bad value of each shared field and the rule its refusal states.
BAD = {
    "unshuffle": (0, "an integer >= 1"),
    "channels": (1.5, "an integer >= 1"),
    "levels": (0, "an integer >= 1"),
    "dcn_kernel": (4, "odd"),
    "max_offset": (float("inf"), "a finite number > 0"),
    "mu": (0.0, "a finite number > 0"),
}


@pytest.mark.parametrize("name", LEARNED)
def test_every_method_shares_the_pyramid_fields_and_their_checks(name):
    sizes_cls = method_classes(name)[1]
    assert issubclass(sizes_cls, PyramidSizes)
    sizes = sizes_cls()
    assert sizes.mu == MU
    assert sizes.pyramid_factor % (sizes.unshuffle << (sizes.levels - 1)) == 0
    for key, (value, rule) in BAD.items():
        with pytest.raises(InputError, match=f"{sizes_cls.LABEL} size {key} = .*: must be {rule}"):
            sizes_cls(**{key: value})


@pytest.mark.parametrize("name", LEARNED)
def test_the_cpu_preset_is_the_defaults_and_the_paper_preset_differs(name):
    sizes_cls = method_classes(name)[1]
    assert SIZE_PRESETS == ("cpu", "paper")
    assert sizes_cls.preset("cpu") == sizes_cls()
    paper = sizes_cls.preset("paper")
    assert paper == sizes_cls(**sizes_cls.PAPER) != sizes_cls()
    with pytest.raises(InputError, match=r"known: cpu, paper"):
        sizes_cls.preset("gpu")


@pytest.mark.parametrize("name", [n for n in LEARNED if n != "net"])
def test_baselines_share_the_tail_sizes(name):
    sizes_cls = method_classes(name)[1]
    assert issubclass(sizes_cls, BaselineSizes)
    with pytest.raises(InputError, match="channels = 16: must be a multiple of offset_groups"):
        sizes_cls(offset_groups=3)
    with pytest.raises(InputError, match="recon_blocks"):
        sizes_cls(recon_blocks=-1)
    assert sizes_cls(recon_blocks=0).recon_blocks == 0


@pytest.mark.parametrize("path", sorted(WEIGHTS_DIR.glob("*.pt")), ids=lambda p: p.name)
def test_shipped_weights_sizes_read_back_by_name(path):
    """Every stored key is a field of the method's sizes, and the sizes give the stored dict back (a field
    renamed, dropped or given another default would show here)."""
    payload = read_weights(path)
    sizes_cls = method_classes(payload["method"])[1]
    sizes = sizes_cls.from_dict(payload["sizes"])
    stored = {key: tuple(v) if isinstance(v, list) else v for key, v in payload["sizes"].items()}
    assert dataclasses.asdict(sizes) == stored
