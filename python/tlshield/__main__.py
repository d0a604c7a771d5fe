"""``python -m tlshield``: the command line."""

from tlshield.lab.cli import main

raise SystemExit(main())
