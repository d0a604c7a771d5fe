"""Tests of the lab (``tlshield.lab``: training, evaluation, the command line, benchmarks, run
folders, plots, seeds, Ray); the library's tests are the ones in ``tests/``."""
