"""``python3 -m tespike``: the ``tespike`` command."""

from tespike.cosim.cli import main

raise SystemExit(main())
