"""``python3 -m tespike``: the ``tespike`` command, through the same entry as the installed script."""

from tespike.entry import run

run()
