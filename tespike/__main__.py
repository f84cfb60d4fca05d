"""``python3 -m tespike``: the ``tespike`` command."""

try:              # Ctrl-C while numpy loads, before the command's own handling: one line, no traceback
    from tespike.cosim.cli import main
except KeyboardInterrupt:
    import sys
    print("tespike: interrupted", file=sys.stderr)
    raise SystemExit(130) from None

raise SystemExit(main())
