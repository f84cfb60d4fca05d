"""Amaranth HDL of the TE and ML pixel, the shared timing and the pixel array."""
