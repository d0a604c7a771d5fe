"""One runner for the benchmarks: jobs, then each job's ``result.json``, then the rows, then
``<name>.csv``, ``<name>.md`` and the figure. A benchmark (FlatWorld's, Safety-Gymnasium's)
describes itself as data, a :class:`Benchmark`: its columns, how its rows sort, its table and
its figure; this module does the rest, the same way for each.

A results folder holds ``runs/<job>/`` per job; a job writes its ``result.json`` last, so a
folder without one is unfinished and runs again (resumable)."""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["RESULT_FILE", "Benchmark", "read_rows", "run", "write_report"]

#: What a finished job leaves in its folder: its row.
RESULT_FILE = "result.json"

Row = dict[str, Any]


def _as_is(row: Row) -> Row:
    return row


@dataclass(frozen=True)
class Benchmark:
    """A benchmark, as data: ``name`` (``<name>.csv`` and ``<name>.md``), the CSV ``columns``,
    the rows' ``order`` (a sort key), the ``markdown`` table of the rows, the ``figure``
    (``figure(out, rows)`` writes its image into ``out``) and ``csv_row``, what a row becomes
    in the CSV (default: itself)."""

    name: str
    columns: tuple[str, ...]
    order: Callable[[Row], Any]
    markdown: Callable[[list[Row]], str]
    figure: Callable[[Path, list[Row]], None]
    csv_row: Callable[[Row], Row] = _as_is


def run(
    bench: Benchmark,
    out: Path,
    jobs: Mapping[Path, Callable[[], Any]],
    address: str | None,
    workers: int | None,
    progress: bool,
) -> Path:
    """Runs the unfinished ``jobs`` (folder -> task, :func:`tlshield.lab.cluster.run_counted`:
    Ray tasks) and writes the report from every finished one; returns ``out``."""
    from tlshield.lab import cluster

    todo = {folder: job for folder, job in jobs.items() if not is_finished(folder)}
    cluster.run_counted(todo, address, workers, progress)
    return write_report(bench, out)


def is_finished(folder: Path) -> bool:
    """Whether the job of ``folder`` wrote its row."""
    return (folder / RESULT_FILE).exists()


def write_result(folder: Path, row: Row) -> None:
    """A job's row, written last (its folder counts as finished from then on)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / RESULT_FILE).write_text(json.dumps(row, indent=2))


def read_rows(bench: Benchmark, out: Path) -> list[Row]:
    """Every finished job's row under ``out/runs``, in the benchmark's order."""
    rows = [json.loads(p.read_text()) for p in sorted((out / "runs").glob(f"*/{RESULT_FILE}"))]
    return sorted(rows, key=bench.order)


def write_report(bench: Benchmark, out: Path) -> Path:
    """``<name>.csv``, ``<name>.md`` and the figure from the finished jobs; returns ``out``."""
    out = Path(out)
    rows = read_rows(bench, out)
    with (out / f"{bench.name}.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=bench.columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(bench.csv_row(r) for r in rows)
    (out / f"{bench.name}.md").write_text(bench.markdown(rows))
    bench.figure(out, rows)
    return out
