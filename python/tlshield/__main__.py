"""``python -m tlshield``: the command line."""

from tlshield.cli import main

raise SystemExit(main())
