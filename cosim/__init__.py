"""Co-simulation of the RTL against the golden model, the outside tools, and the ``tespike`` command line.

Simulators: :mod:`.rtlsim` (Amaranth), :mod:`.verilator`, :mod:`.icarus`, :mod:`.cocotb_run`,
each on the tops of :mod:`.tops`, checked by :mod:`.backends` and :mod:`.compare`;
:mod:`.formal` (the proofs); :mod:`.synthesis`, :mod:`.activity`, :mod:`.gate_activity` and
:mod:`.energy` (cost and energy per readout); :mod:`.vcd` (waveforms). The command:
:mod:`.cli` and :mod:`.commands` (one module per sub-command), :mod:`.console`, :mod:`.room`,
:mod:`.children`; :mod:`.demo` (circuit to image); :mod:`.dataset` (Dask).
"""
