"""Figures and the results table of a results folder (tiny real runs: 2 configs x 2 seeds x 3
updates, evaluated on 3 trials), including partial folders: no runs, a run without metric
rows or evaluation, a metrics row cut short."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")
pytest.importorskip("stable_baselines3")

from tlshield.lab import plots
from tlshield.lab.evaluation import evaluate
from tlshield.lab.plots import FIGURES, plot_all
from tlshield.lab.report import TABLE_COLUMNS, results_table
from tlshield.lab.runs import METRIC_COLUMNS, load_results
from tlshield.lab.training import train

CONFIGS = ("rl", "rl_cbf_clf")
SEEDS = (0, 1)
UPDATES = 3
TRIALS = 3
#: The small files of a run folder (what plotting reads).
RUN_FILES = ("run.json", "metrics.csv", "evaluation.json", "trajectories.npz")


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("results")
    for config in CONFIGS:
        for seed in SEEDS:
            # The paper preset's updates are whole episodes, so every update has a return.
            run = train(
                config, seed, UPDATES, root / f"{config}_s{seed}", progress=False, preset="paper"
            )
            evaluate(run, trials=TRIALS)
    return root


def copy_results(results: Path, target: Path) -> Path:
    """A copy of the plotted files of every run of ``results``."""
    for run in results.iterdir():
        if run.is_dir() and (run / "run.json").is_file():
            (target / run.name).mkdir(parents=True)
            for name in RUN_FILES:
                if (run / name).is_file():
                    shutil.copy(run / name, target / run.name / name)
    return target


def assert_images(paths: list[Path]) -> None:
    from matplotlib.image import imread

    assert [p.name for p in paths] == list(FIGURES)
    for path in paths:
        image = imread(path)
        assert image.ndim == 3 and min(image.shape[:2]) > 200, path.name
        gray = image[..., :3].mean(axis=2)
        assert gray.min() < 0.3 and gray.max() > 0.9, path.name  # dark ink on white
        assert (gray < 0.95).mean() > 0.01, path.name  # not an almost empty canvas


def test_load_results(results: Path) -> None:
    groups = load_results(results)
    assert list(groups) == list(CONFIGS)
    for config, runs in groups.items():
        assert [r.seed for r in runs] == list(SEEDS)
        for run in runs:
            assert run.config == config and run.updates == UPDATES
            assert set(run.metrics) == set(METRIC_COLUMNS)
            assert run.metrics["update"].tolist() == [1.0, 2.0, 3.0]
            assert run.evaluation is not None and run.evaluation["trials"] == TRIALS
            assert run.trajectories is not None
            starts, paths = run.trajectories
            assert starts.shape == (TRIALS, 13) and len(paths) == TRIALS
            assert all(p.ndim == 2 and p.shape[1] == 2 for p in paths)
            assert run.env.obstacles.obstacle_radius == pytest.approx(0.3)


def test_plot_all_writes_decodable_figures(results: Path, tmp_path: Path) -> None:
    paths = plot_all(results, tmp_path / "figs")
    assert all(p.parent == tmp_path / "figs" for p in paths)
    assert_images(paths)
    default = plot_all(results)  # default: results/figures
    assert all(p.parent == results / "figures" and p.is_file() for p in default)
    assert load_results(results).keys() == set(CONFIGS)  # the figures folder is not a run


def test_automaton_without_graphviz(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(plots.automaton.shutil, "which", lambda name: None)
    path = plots.automaton._plot_automaton(tmp_path / "task_automaton.png")
    from matplotlib.image import imread

    gray = imread(path)[..., :3].mean(axis=2)
    assert gray.min() < 0.3 and (gray < 0.95).mean() > 0.01


def test_results_table(results: Path) -> None:
    lines = results_table(results).splitlines()
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    assert header == list(TABLE_COLUMNS)
    assert set(lines[1]) <= set("|-: ")
    rows = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines[2:]]
    assert [row[0] for row in rows] == list(CONFIGS)
    for row in rows:
        assert len(row) == len(TABLE_COLUMNS)
        assert row[1] == "0, 1" and row[2] == str(UPDATES)
        assert "±" in row[6] and "±" in row[7]
        assert f"2 x {TRIALS} trials" in row[8]
        assert row[9].endswith(f"/ {len(SEEDS) * TRIALS}")
    shielded = rows[CONFIGS.index("rl_cbf_clf")]
    assert shielded[3] == "0"  # the CBF keeps training inside the channel


def test_no_runs(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no runs"):
        load_results(tmp_path)
    (tmp_path / "notes").mkdir()  # a folder without run.json is not a run
    with pytest.raises(FileNotFoundError, match="no runs"):
        plot_all(tmp_path)
    with pytest.raises(FileNotFoundError, match="no such results folder"):
        results_table(tmp_path / "missing")


def test_partial_runs_are_tolerated(results: Path, tmp_path: Path) -> None:
    root = copy_results(results, tmp_path / "partial")
    # A run that has not finished its first update: header-only metrics, no evaluation.
    empty = root / "rl_cbf_s0"
    empty.mkdir()
    record = json.loads((root / "rl_s0" / "run.json").read_text())
    (empty / "run.json").write_text(json.dumps({**record, "config": "rl_cbf"}))
    (empty / "metrics.csv").write_text(",".join(METRIC_COLUMNS) + "\n")
    # An interrupted run: its last metrics row was cut short, its evaluation is missing.
    cut = root / "rl_s1"
    text = (cut / "metrics.csv").read_text()
    (cut / "metrics.csv").write_text(text + "4,4000,5,-1")
    (cut / "evaluation.json").unlink()
    (cut / "trajectories.npz").unlink()
    # A seed-0 run without trajectories: the trajectory panel falls back to seed 1.
    (root / "rl_cbf_clf_s0" / "trajectories.npz").unlink()

    groups = load_results(root)
    assert list(groups) == ["rl", "rl_cbf", "rl_cbf_clf"]
    (run,) = groups["rl_cbf"]
    assert run.updates == 0 and run.evaluation is None and run.trajectories is None
    assert groups["rl"][1].updates == UPDATES

    assert_images(plot_all(root))
    lines = results_table(root).splitlines()
    assert len(lines) == 2 + 3
    row = [cell.strip() for cell in lines[3].strip("|").split("|")]
    assert row[0] == "rl_cbf" and row[2] == "0"
    assert all(cell == "—" for cell in row[3:])
    rl = [cell.strip() for cell in lines[2].strip("|").split("|")]
    assert f"1 x {TRIALS} trials" in rl[8]


def test_only_missing_pieces(results: Path, tmp_path: Path) -> None:
    """Every run without metric rows and evaluation: figures say so, nothing crashes."""
    root = tmp_path / "bare"
    for config in CONFIGS:
        run = root / f"{config}_s0"
        run.mkdir(parents=True)
        shutil.copy(results / f"{config}_s0" / "run.json", run / "run.json")
        (run / "metrics.csv").write_text("")
    paths = plot_all(root, tmp_path / "figs")
    assert [p.name for p in paths] == list(FIGURES) and all(p.is_file() for p in paths)
    table = results_table(root)
    assert table.count("\n") == 1 + len(CONFIGS)
    assert np.all([line.count("—") >= 8 for line in table.splitlines()[2:]])
