"""Training, evaluation and the command line, end to end with tiny budgets (real SB3 PPO)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from tlshield.lab import cli
from tlshield.lab.evaluation import EVAL_SEED, evaluate
from tlshield.lab.presets import clf_scale
from tlshield.lab.runs import METRIC_COLUMNS
from tlshield.lab.training import train


def read_metrics(run: Path) -> list[dict[str, str]]:
    with (run / "metrics.csv").open() as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train("rl_cbf_clf", 0, 3, tmp_path_factory.mktemp("runs") / "x", progress=False)


def test_run_folder_holds_everything(run: Path) -> None:
    files = {p.name for p in run.iterdir()}
    assert files >= {"run.json", "metrics.csv", "model.zip", "last_model.zip", "tb"}
    rows = read_metrics(run)
    assert len(rows) == 3 and tuple(rows[0]) == METRIC_COLUMNS
    assert [int(r["timesteps"]) for r in rows] == [1024, 2048, 3072]
    assert all(int(r["violations"]) == 0 for r in rows)  # the CBF is on
    record = json.loads((run / "run.json").read_text())
    assert record["finished"] and record["config"] == "rl_cbf_clf"
    assert record["preset"] == "default" and record["n_envs"] == 8
    assert record["ppo"]["net_arch"] == {"pi": [64, 64], "vf": [64, 64]}
    assert record["env"]["gamma"] == record["ppo"]["gamma"] == 0.999
    assert "kept" not in record  # no validation within 3 updates: the last policy is kept
    assert any((run / "tb").iterdir())


def test_paper_preset_and_validation(tmp_path: Path) -> None:
    from tlshield.envs.channel import PAPER_ENV
    from tlshield.lab.presets import PRESETS

    paper = train("rl_cbf", 1, 1, tmp_path / "p", progress=False, preset="paper", **PAPER_ENV)
    record = json.loads((paper / "run.json").read_text())
    assert record["ppo"]["net_arch"] == {"pi": [300, 200, 100], "vf": [300, 200, 100]}
    assert record["n_envs"] == 5 and read_metrics(paper)[0]["timesteps"] == "1000"
    assert record["env"]["reward"] == "paper" and record["env"]["gamma"] == 0.99
    every = PRESETS["default"]["validate_every"]
    checked = train("rl_cbf_clf", 2, every, tmp_path / "v", progress=False)
    record = json.loads((checked / "run.json").read_text())
    rows = read_metrics(checked)
    assert record["kept"]["update"] == every
    assert float(rows[-1]["validation_success"]) == record["kept"]["validation_success"]
    assert all(r["validation_success"] == "nan" for r in rows[:-1])


def test_evaluation(run: Path) -> None:
    result = evaluate(run, trials=3)
    assert result["trials"] == 3 and 0.0 <= result["success_rate"] <= 1.0
    assert result["violation_steps"] == 0
    # Give-ways by barrier and contacts the shield did not report are counted (issue 57).
    assert isinstance(result["gave_way"], dict) and result["unreported_contacts"] == 0
    assert all("gave_way" in o for o in result["outcomes"])
    saved = json.loads((run / "evaluation.json").read_text())
    assert saved == result
    data = np.load(run / "trajectories.npz")
    assert data["starts"].shape == (3, 13) and data["lengths"].sum() == len(data["paths"])
    assert data["obstacle_paths"].shape == (len(data["paths"]), 4)
    outcomes = result["outcomes"]
    assert [o["reset_seed"] for o in outcomes] == [EVAL_SEED, EVAL_SEED + 1, EVAL_SEED + 2]
    assert sum(o["success"] for o in outcomes) == result["successes"]
    assert [o["steps"] + 1 for o in outcomes] == data["lengths"].tolist()


def test_seeded_runs_are_deterministic(tmp_path: Path) -> None:
    # Any non-negative seed: numpy's legacy seeding (inside SB3) takes only 32 bits, so PPO
    # gets tlshield.lab.seeds.learner_seed.
    a = read_metrics(train("rl_cbf", 2**40, 2, tmp_path / "a", progress=False))
    b = read_metrics(train("rl_cbf", 2**40, 2, tmp_path / "b", progress=False))
    strip = lambda rows: [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]  # noqa: E731
    assert strip(a) == strip(b)


def test_clf_schedules(tmp_path: Path) -> None:
    assert clf_scale("fixed", 0.7, 0.2) == 1.0
    assert clf_scale("linear", 1.0, 0.2) == pytest.approx(0.2)
    assert clf_scale("exponential", 0.5, 0.25) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="schedule"):
        clf_scale("cosine", 0.5, 0.2)
    run = train("rl_clf", 1, 3, tmp_path / "s", clf_schedule="linear", progress=False)
    scales = [float(r["clf_scale"]) for r in read_metrics(run)]
    assert scales == pytest.approx([1.0, 0.6, 0.2])


def _largest_clf_push(run: object, steps: int = 40) -> np.ndarray:
    """The largest |a_clf| per action dimension over a few zero-action steps of the run's
    training environments (the CLF pushes towards the goal, up to its box)."""
    inner = run.inner  # type: ignore[attr-defined]
    inner.reset()
    largest = np.zeros(2)
    for _ in range(steps):
        infos = inner.step(np.zeros((inner.num_envs, 2)))[3]
        for info in infos:
            largest = np.maximum(largest, np.abs(info["shield"]["a_clf"]))
    return largest


def test_the_clf_schedule_scales_the_training_environments_box(tmp_path: Path) -> None:
    """Not only the logged scale: the shield the training environments step with has its CLF
    box scaled (Channel-v0's rescaler, built by prepare, not the callback)."""
    from tlshield.envs.channel import ChannelParams
    from tlshield.lab.training import prepare

    run = prepare("rl_clf", 1, 3, tmp_path / "s", clf_schedule="linear", progress=False)
    assert run.rescale_clf is not None
    lo, hi = ChannelParams().shield.clf_bounds
    box = np.maximum(np.abs(lo), np.abs(hi))
    full = _largest_clf_push(run)
    assert np.any(full > 0.3 * box), "the CLF should push harder than the scaled box allows"
    run.rescale_clf(0.3)
    scaled = _largest_clf_push(run)
    assert np.all(scaled <= 0.3 * box + 1e-9) and np.any(scaled > 0.0)
    fixed = prepare("rl_clf", 1, 3, tmp_path / "f", progress=False)
    assert fixed.rescale_clf is None  # the paper's fixed bounds: nothing to rescale


def test_bad_training_arguments(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="config"):
        train("rl_cbf_clf_x", 0, 1, tmp_path / "bad")
    with pytest.raises(ValueError, match="updates"):
        train("rl", 0, 0, tmp_path / "bad")
    with pytest.raises(ValueError, match="scale"):
        train("rl", 0, 1, tmp_path / "bad", clf_final_scale=2.0)
    for seed in (-1, 1.5):
        with pytest.raises(ValueError, match=r"seed = .*expected a non-negative integer"):
            train("rl", seed, 1, tmp_path / "bad")
    with pytest.raises(FileNotFoundError, match="not a tlshield run"):
        evaluate(tmp_path / "missing")
    with pytest.raises(ValueError, match="trials"):
        evaluate(tmp_path, trials=0)


def test_cli_help_and_errors(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    for command in ("train", "evaluate", "reproduce", "ablation", "tune", "plot", "fsa"):
        with pytest.raises(SystemExit) as exit_info:
            cli.main([command, "--help"])
        assert exit_info.value.code == 0
        assert "usage: tlshield " + command in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["train", "--config", "nope", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
    with pytest.raises(SystemExit, match=r"^2$"):
        cli.main(["train", "--updates", "-3", "--out", str(tmp_path)])
    assert "positive integer" in capsys.readouterr().err
    assert cli.main(["evaluate", str(tmp_path / "missing")]) == 2
    assert "not a tlshield run folder" in capsys.readouterr().err
    assert cli.main(["plot", str(tmp_path / "empty")]) == 2


def test_cli_train_and_evaluate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli_run"
    code = cli.main(
        [
            "train",
            "--config",
            "rl",
            "--updates",
            "1",
            "--out",
            str(out),
            "--quiet",
            "--evaluate",
            "--trials",
            "2",
        ]
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "wrote" in printed and "success" in printed
    assert (out / "evaluation.json").is_file()


def test_cli_without_the_training_extra_names_it(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # None in sys.modules makes `import torch` raise ModuleNotFoundError, as when the extra
    # is not installed.
    import sys

    for name in ("torch", "stable_baselines3"):
        monkeypatch.setitem(sys.modules, name, None)
    code = cli.main(["train", "--updates", "1", "--out", str(tmp_path / "r"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "pip install 'tlshield[train]'" in err and "Traceback" not in err


def test_train_and_evaluate_point_mass_from_the_cli(tmp_path: Path) -> None:
    # Tiny budget: the plumbing (env choice, metrics, validation, evaluation), not learning.
    out = tmp_path / "pm"
    args = ["train", "--env", "tlshield/PointMass-v0", "--config", "rl_cbf_clf"]
    assert cli.main([*args, "--updates", "1", "--out", str(out), "--quiet"]) == 0
    record = json.loads((out / "run.json").read_text())
    assert record["env_id"] == "tlshield/PointMass-v0" and record["finished"]
    rows = read_metrics(out)
    assert len(rows) == 1 and int(rows[0]["violations"]) == 0  # the HOCBF holds in training
    # The constraint columns are the env's own (obstacles o1, o2), measured, not Channel's.
    from tlshield.lab.runs import load_run, metric_columns

    assert tuple(rows[0]) == metric_columns(("o1", "o2"))
    assert min(float(rows[0]["min_h_o1"]), float(rows[0]["min_h_o2"])) >= 0.0
    loaded = load_run(out)
    assert loaded is not None and loaded.metrics["min_h_o2"].shape == (1,)
    result = evaluate(out, trials=3)
    assert result["trials"] == 3 and len(result["outcomes"]) == 3
    assert result["collisions"] == 0
    with pytest.raises(ValueError, match=r"has none .* use 'fixed'"):
        train("rl_clf", 0, 1, tmp_path / "x", env="tlshield/PointMass-v0", clf_schedule="linear")


def test_the_progress_bar_shows_the_run_so_far() -> None:
    """Issue 57: the bar showed ``ret=nan`` in every update where no episode ended, and its
    ``viol=`` counted only the last update (101 violating steps in training showed as 0)."""
    from tlshield.lab.callbacks import RunTotals

    totals = RunTotals()
    row = {"violations": 101.0, "relaxed": 3, "failed": 0}
    totals.gave_way.update({"!o1": 2})
    shown = totals.add(row)
    assert shown == {"ret": "-", "viol": "101", "relaxed": "3", "failed": "0", "gave_way": "2"}
    totals.returns.extend([10.0, 20.0])
    assert totals.add({**row, "violations": 0.0})["ret"] == "15.0"
    # An update where no episode ended keeps the last returns; counts add up.
    shown = totals.add({"violations": 0.0, "relaxed": 1, "failed": 2})
    assert shown == {
        "ret": "15.0",
        "viol": "101",
        "relaxed": "7",
        "failed": "2",
        "gave_way": "2",
    }
    # Not measured (an env that reports no violations): n/a, never 0.
    assert RunTotals().add({"violations": float("nan"), "relaxed": 0, "failed": 0})["viol"] == "n/a"
    totals.returns.extend(float(k) for k in range(100))  # the last RunTotals.RECENT only
    assert totals.add(row)["ret"] == f"{sum(range(80, 100)) / 20:.1f}"


def test_an_episode_that_touched_an_obstacle_is_never_counted_a_success() -> None:
    """Issue 57, item 4: on Channel-v0 with the obstacles as the shield's barriers only (not in
    the formula), the env accepts an episode that touched one on the way; training's success
    count does not (evaluation ends a trial at its first contact, and a contact on the step of
    acceptance is not a success either). The unshielded env, driven straight ahead."""
    import gymnasium as gym

    from tlshield.lab.callbacks import UpdateMetrics

    env = gym.make("tlshield/Channel-v0", config="rl")
    metrics = UpdateMetrics(1, 0.99)
    accepted_after_contact = clean = 0
    for seed in range(60):
        env.reset(seed=seed)
        touched = False
        while True:
            _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0]))
            touched |= bool(info["collision"])
            metrics.step(np.array([reward]), np.array([terminated or truncated]), [info])
            if terminated or truncated:
                accepted_after_contact += bool(info["success"]) and touched
                clean += bool(info["success"]) and not touched
                break
    env.close()
    assert accepted_after_contact > 0, "no episode touched and was accepted: cannot fail"
    assert metrics.successes == clean
