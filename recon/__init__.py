"""Reconstruction of HDR images from TE and ML spike streams (torch, CPU-first)."""
