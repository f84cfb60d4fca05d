#!/bin/sh
# Install tespike and the outside tools it drives (Icarus Verilog, Verilator, Yosys, z3, boolector).
# Debian packages need root (or sudo); Python packages go to the active interpreter.
set -eu
cd "$(dirname "$0")"
missing=""
for tool in iverilog verilator yosys z3 boolector; do
  command -v "$tool" >/dev/null 2>&1 || missing="$missing $tool"
done
if [ -n "$missing" ]; then
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $missing >/dev/null
fi
python3 -m pip install -q torch==2.13.0          # pinned: the CPU build (a looser pin pulls CUDA)
python3 -m pip install -q -e '.[test]'
# Bytecode compiled once, as a wheel install does: an editable install leaves it to each
# run, and where PYTHONDONTWRITEBYTECODE is set every command compiled its ~40 modules
# again (about 0.1 s of each `tespike simulate`; python3 benchmarks/bench_startup.py).
python3 -m compileall -q golden rtl recon cosim tespike || echo "install.sh: bytecode not compiled (each command starts about 0.1 s slower)" >&2
