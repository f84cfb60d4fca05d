"""The Verilog module names of the generated text: the one place they are written.

SPEC section 6 names the tops (``<mode>_pixel_array``, ``<mode>_pixel_array_stream``);
the modules below them are this project's. Every reader of the text (the
simulator harnesses, the proofs, synthesis, the energy figures) takes its names
from here; no amaranth is imported, so a harness that only reads a file pays nothing.
"""

from __future__ import annotations

from tespike.golden.config import SensorConfig


def module_names(config: SensorConfig) -> dict[str, str]:
    """Verilog module names, prefixed by the mode: ``top``, ``pixel``, ``timing`` (the sampled-input
    timing block of the pixel and the streaming top) and ``array_timing`` (the parallel top's,
    ``ReadoutTiming(sampled_input=False)``)."""
    mode = SensorConfig.required(config, "module_names").mode
    return {"top": f"{mode}_pixel_array", "pixel": f"{mode}_pixel", "timing": f"{mode}_readout_timing",
            "array_timing": f"{mode}_array_timing"}


def stream_module_names(config: SensorConfig) -> dict[str, str]:
    """Module names of the streaming Verilog: ``top`` (``<mode>_pixel_array_stream``),
    ``timing``, ``pixel`` (one site's pixel), ``rule`` (its combinational rule), ``cell``
    (one readout cell), ``group`` and ``group_end`` (the sites whose words leave in one beat; the
    end group, the last beat's, shifts in 0)."""
    config = SensorConfig.required(config, "stream_module_names")
    names = module_names(config)
    mode = config.mode
    return {"top": names["top"] + "_stream", "timing": names["timing"], "pixel": f"{mode}_stream_pixel",
            "rule": f"{mode}{'_msb' if config.is_msb else ''}_stream_pixel_rule",
            "cell": f"{mode}_readout_cell", "group": f"{mode}_beat_group",
            "group_end": f"{mode}_beat_group_end"}
