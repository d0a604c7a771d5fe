"""Hypothesis runs derandomized (a fixed seed per test), so a failure on one machine is the
same failure on every machine and in CI; ``HYPOTHESIS_PROFILE=explore`` draws fresh examples."""

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("explore", print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
