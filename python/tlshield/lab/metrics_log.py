"""``metrics.csv`` as an output format of SB3's logger: the training callbacks record each
update's metrics in the model's logger (``tlshield/<column>``), as SB3 records its own
``train/`` and ``time/`` values, and the logger writes them out when it dumps, once per
update: to ``metrics.csv`` (:class:`MetricsCsv`) and to TensorBoard. Importing this module
loads SB3."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from stable_baselines3.common.logger import KVWriter, Logger, make_output_format

__all__ = ["PREFIX", "MetricsCsv", "run_logger"]

#: The logger keys of the metrics (``tlshield/return_mean``); TensorBoard shows them under it.
PREFIX = "tlshield/"
#: Columns that count updates rather than measure them: kept out of TensorBoard, whose own
#: step axis is the timestep.
COUNTERS = ("update", "timesteps")


class MetricsCsv(KVWriter):  # type: ignore[misc]
    """The run's ``metrics.csv`` (:func:`tlshield.lab.runs.metric_columns`): at each dump that
    holds the metrics (``tlshield/<column>`` keys), one row in the declared column order, flushed
    at once (a stopped run keeps every update it finished). SB3's ``CSVOutputFormat`` is not
    used because it orders columns that arrive later by a set's order and writes SB3's own
    keys too; the readers need neither."""

    def __init__(self, path: str | Path, columns: Sequence[str]) -> None:
        self.file = Path(path).open("w", newline="")
        self.columns = tuple(columns)
        self.writer = csv.DictWriter(self.file, fieldnames=self.columns)
        self.writer.writeheader()
        self.file.flush()

    def write(
        self, key_values: dict[str, Any], key_excluded: dict[str, tuple[str, ...]], step: int = 0
    ) -> None:
        """Writes the dump's metrics as one row; a dump without them writes nothing."""
        if f"{PREFIX}{self.columns[0]}" not in key_values:
            return
        self.writer.writerow({c: key_values[f"{PREFIX}{c}"] for c in self.columns})
        self.file.flush()

    def close(self) -> None:
        """Closes the file."""
        self.file.close()


def run_logger(folder: Path, columns: Sequence[str]) -> Logger:
    """The logger of one run: ``metrics.csv`` in ``folder`` and TensorBoard under
    ``folder/tb``."""
    tensorboard = make_output_format("tensorboard", str(folder / "tb"))
    return Logger(str(folder), [MetricsCsv(folder / "metrics.csv", columns), tensorboard])


def record_row(logger: Logger, row: dict[str, Any]) -> None:
    """Records one update's metrics row in ``logger`` (written at its next dump)."""
    for key, value in row.items():
        logger.record(f"{PREFIX}{key}", value, exclude="tensorboard" if key in COUNTERS else None)
