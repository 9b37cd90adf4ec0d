"""``python -m depth``: see :mod:`depth.cli`."""

from depth.cli import main

raise SystemExit(main())
