"""Package layout: the rooms ``golden/``, ``rtl/``, ``cosim/`` and ``recon/`` install
as ``tespike.golden``, ``tespike.rtl``, ... (import names of tespike's own; the bare
names belong to unrelated packages on the Python package index)."""

from setuptools import find_packages, setup

ROOMS = ("golden", "rtl", "cosim", "recon")

packages = ["tespike"]
for room in ROOMS:
    packages += [f"tespike.{room}"] + [f"tespike.{room}.{sub}" for sub in find_packages(room)]

setup(packages=packages, package_dir={"tespike": "tespike", **{f"tespike.{room}": room for room in ROOMS}})
