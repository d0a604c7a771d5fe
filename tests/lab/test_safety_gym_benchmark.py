"""Safety-Gymnasium in the lab (issue 33): the benchmark trains through the pipeline, writes its
table and resumes; validation keeps the best return and the update log counts the cost; the
command line refuses what the suite does not take. The envs themselves: tests/test_safety_gym.py.

``make test`` installs the stack (scripts/setup-safety-gym.sh), so these tests run in CI."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from tlshield.lab import cli

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # gymnasium's Box casts


def test_the_benchmark_trains_through_the_pipeline_and_resumes(tmp_path: Path) -> None:
    from tlshield.lab import benchmark_safety_gym as bench
    from tlshield.lab.runs import load_run

    def run() -> Path:
        return bench.safety_gym(
            tmp_path,
            envs=["SafetyPointGoal1-v0"],
            configs=["rl_cbf+penalty"],
            seeds=[0],
            steps=64,
            episodes=1,
            workers=1,
            progress=False,
        )

    out = run()
    with open(out / "safety_gym.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [tuple(rows[0])] == [bench.COLUMNS] and len(rows) == 1
    row = rows[0]
    assert row["method"] == "rl_cbf+penalty" and int(row["steps"]) == 2048  # one update
    assert float(row["kept_cost"]) == 0.0 and float(row["last_cost"]) == 0.0
    assert float(row["train_cost"]) == 0.0
    assert (out / "safety_gym.png").stat().st_size > 0
    text = (out / "safety_gym.md").read_text()
    assert "privileged" in text and "kept return" in text and "last return" in text
    # The job's folder is a tlshield run folder: the preset, the lever's setting, cost per
    # update, both policies evaluated on their return and cost.
    folder = next((out / "runs").glob("*/result.json")).parent
    loaded = load_run(folder)
    assert loaded is not None and loaded.record["preset"] == "safety-gym"
    assert loaded.record["overrides"] == {"correction_penalty": 0.01}
    assert loaded.record["env"]["correction_penalty"] == 0.01
    assert loaded.metrics["cost"].tolist() == [0.0]
    assert loaded.evaluation is not None and loaded.last_evaluation is not None
    for evaluation in (loaded.evaluation, loaded.last_evaluation):
        assert evaluation["cost_mean"] == 0.0 and evaluation["outcomes"][0]["steps"] == 1000
    before = (folder / "result.json").read_text()
    run()
    assert (folder / "result.json").read_text() == before  # kept, not re-run


def test_validation_keeps_the_best_return_and_metrics_count_the_cost(tmp_path: Path) -> None:
    """Unshielded, with a short rollout: the update log sums Safety-Gymnasium's cost and the
    undiscounted return, and validation on the return keeps a policy whose record says it."""
    from tlshield.lab.runs import load_run
    from tlshield.lab.training import learn, prepare

    run = prepare(
        "rl",
        3,
        10,
        tmp_path,
        progress=False,
        preset="safety-gym",
        ppo={"n_steps": 256, "batch_size": 64, "n_epochs": 1},
        env="tlshield/SafetyPointGoal1-v0",
    )
    learn(run)
    loaded = load_run(tmp_path)
    assert loaded is not None
    m = loaded.metrics
    assert len(m["update"]) == 10
    # 2,560 steps: two 1,000-step episodes ended, in updates 4 and 8.
    ended = np.flatnonzero(~np.isnan(m["task_return_mean"])).tolist()
    assert ended == [3, 7]
    assert np.all(m["cost"] >= 0) and not np.isnan(m["cost"]).any()
    assert np.isnan(m["validation_return"][:9]).all() and not np.isnan(m["validation_return"][9])
    kept = loaded.record["kept"]
    assert kept["update"] == 10 and kept["validation_return"] == m["validation_return"][9]
    assert kept["validation_cost"] == m["validation_cost"][9]
    assert (tmp_path / "model.zip").is_file() and (tmp_path / "last_model.zip").is_file()


def test_sensing_is_a_column_and_a_lidar_row_reads_no_privileged_state(tmp_path: Path) -> None:
    from tlshield.lab import benchmark_safety_gym as bench
    from tlshield.lab.runs import load_run

    out = bench.safety_gym(
        tmp_path,
        envs=["SafetyPointGoal1-v0"],
        configs=["rl_cbf_clf", "rl"],
        seeds=[0],
        sensing=["state", "lidar"],
        steps=64,
        episodes=1,
        workers=1,
        progress=False,
    )
    with open(out / "safety_gym.csv") as fh:
        rows = {r["sensing"]: r for r in csv.DictReader(fh) if r["method"] == "rl_cbf_clf"}
        fh.seek(0)
        unshielded = [r for r in csv.DictReader(fh) if r["method"] == "rl"]
    assert sorted(rows) == ["lidar", "state"]
    # The unshielded row reads nothing: one job, whatever the modes asked for.
    assert [r["sensing"] for r in unshielded] == ["none"]
    for row in rows.values():
        assert float(row["kept_cost"]) == 0.0 and float(row["train_cost"]) == 0.0
    # The lidar row trained and was evaluated with the lidar mode; the state row's folder keeps
    # the name and the settings it had before the column.
    lidar = load_run(
        out / "runs" / bench.folder_name("SafetyPointGoal1-v0", "rl_cbf_clf", 0, 64, "lidar")
    )
    state = load_run(out / "runs" / "SafetyPointGoal1-v0-rl_cbf_clf-s0-64")
    assert lidar is not None and lidar.record["overrides"] == {"sensing": "lidar"}
    assert state is not None and state.record["overrides"] == {}
    text = (out / "safety_gym.md").read_text()
    assert "| SafetyPointGoal1-v0 | rl_cbf_clf | lidar | 0 |" in text
    assert "| SafetyPointGoal1-v0 | rl_cbf_clf | state | 0 |" in text
    assert "sensing` = lidar the shield reads only the policy's own observation" in text
    assert "like for like with the rows read from the lidar" in text
    with pytest.raises(ValueError, match="sensing 'radar'"):
        bench.safety_gym(tmp_path, envs=["SafetyPointGoal1-v0"], sensing=["radar"])


def test_the_cli_refuses_what_the_suite_does_not_take(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["benchmark", "safety-gym", "--formulas", "F a"]) == 2
    assert "--formulas" in capsys.readouterr().err
    assert cli.main(["benchmark", "safety-gym", "--envs", "SafetyCarGoal2-v0"]) == 2
    assert "SafetyCarGoal2-v0" in capsys.readouterr().err
    assert cli.main(["benchmark", "safety-gym", "--configs", "rl_cbf+nothing"]) == 2
    assert "rl_cbf+penalty" in capsys.readouterr().err  # the error lists the known rows
    assert cli.main(["benchmark", "safety-gym", "--sensing", "radar"]) == 2
    assert "radar" in capsys.readouterr().err
    assert cli.main(["benchmark", "flatworld", "--sensing", "lidar"]) == 2
    assert "--sensing" in capsys.readouterr().err
