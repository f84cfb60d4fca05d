"""Co-simulation of the RTL against the golden model, and the ``tespike`` command line."""
