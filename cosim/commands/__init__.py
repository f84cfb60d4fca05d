"""One module per ``tespike`` sub-command: ``HELP``, ``add_arguments``, ``run``."""
