"""``python -m depth``: see :mod:`depth.cli`. Ctrl-C while the modules load ends the
same way as during a run: one line, exit status 130."""

import sys

try:
    from depth.cli import main
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    raise SystemExit(130) from None

raise SystemExit(main())
