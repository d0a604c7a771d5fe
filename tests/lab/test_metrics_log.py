"""metrics.csv and TensorBoard as the outputs of SB3's logger (:mod:`tlshield.lab.metrics_log`):
the callbacks record, the logger writes."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tlshield.lab import callbacks
from tlshield.lab.metrics_log import run_logger
from tlshield.lab.runs import _read_metrics, metric_columns


def test_the_logger_writes_metrics_csv_in_the_declared_order_and_tensorboard(
    tmp_path: Path,
) -> None:
    columns = metric_columns(("o1", "o2"))
    logger = run_logger(tmp_path, columns)
    for update in (1, 2):
        # SB3's own values and the metrics in the same dump, keys in an arbitrary order.
        logger.record("train/approx_kl", 0.01 * update)
        for c in reversed(columns):
            value = math.nan if c == "min_h_o2" else float(update)
            logger.record(f"tlshield/{c}", value, exclude="tensorboard" if c == "update" else None)
        logger.dump(step=update * 100)
    logger.record("time/fps", 10)  # a dump without the metrics writes no row
    logger.dump(step=300)
    logger.close()
    with (tmp_path / "metrics.csv").open(newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == list(columns) and len(rows) == 3
    read = _read_metrics(tmp_path / "metrics.csv")
    assert list(read["update"]) == [1.0, 2.0] and all(math.isnan(x) for x in read["min_h_o2"])
    events = EventAccumulator(str(tmp_path / "tb"))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    assert {"tlshield/return_mean", "train/approx_kl"} <= tags
    assert "tlshield/update" not in tags  # the counters stay out of TensorBoard
    assert [e.step for e in events.Scalars("tlshield/return_mean")] == [100, 200]


def test_no_csv_writer_in_the_callbacks() -> None:
    source = Path(callbacks.__file__).read_text()
    assert "import csv" not in source and "DictWriter" not in source
