"""Sweeps and the search on a real Ray (tiny budgets): the local Ray started inside the
command, a cluster started by `ray start --head` reached through --address, resuming, a worker
that dies, and the named settings that tune writes and train reads."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tlshield.lab import cli, cluster, settings
from tlshield.lab.training import reproduce, train

RAY = str(Path(sys.executable).parent / "ray")
#: A guard against hangs, not a speed target: far above what each command takes here.
HANG = 600


def metrics_without_times(run: Path) -> list[dict[str, str]]:
    with (run / "metrics.csv").open() as f:
        return [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(f)]


def command(*args: str) -> list[str]:
    return [sys.executable, "-m", "tlshield", *args]


def clean_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_two_job_reproduce_on_the_local_ray_matches_training_in_process(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = reproduce(
        tmp_path / "out", configs=("rl_cbf_clf",), seeds=(0, 1), updates=2, trials=3, workers=2
    )
    err = capsys.readouterr().err
    assert "runs" in err and "update" not in err  # the bar counts runs, not updates
    assert (root / "results.md").is_file() and (root / "figures").is_dir()
    assert sorted(p.name for p in root.iterdir() if not p.name.startswith(".")) == [
        "figures",
        "results.md",
        "rl_cbf_clf_s0",
        "rl_cbf_clf_s1",
    ]
    for seed in (0, 1):
        run = root / f"rl_cbf_clf_s{seed}"
        assert json.loads((run / "evaluation.json").read_text())["trials"] == 3
        # The same numbers as the same run trained in this process.
        here = train("rl_cbf_clf", seed, 2, tmp_path / f"here{seed}", progress=False)
        assert metrics_without_times(run) == metrics_without_times(here)


def test_pack_and_unpack_replace_a_folder_whole(tmp_path: Path) -> None:
    src = tmp_path / "src"
    (src / "tb").mkdir(parents=True)
    (src / "a.txt").write_text("new")
    (src / "tb" / "b.bin").write_bytes(bytes(range(256)))
    dst = tmp_path / "out" / "run"
    dst.mkdir(parents=True)
    (dst / "stale.txt").write_text("from an older run")
    cluster.unpack(cluster.pack(src), dst)
    assert sorted(str(p.relative_to(dst)) for p in dst.rglob("*")) == ["a.txt", "tb", "tb/b.bin"]
    assert (dst / "tb" / "b.bin").read_bytes() == bytes(range(256))
    assert not list((tmp_path / "out").glob(".*"))  # no .incoming left behind


def test_an_unreachable_address_fails_fast_with_a_clear_error(tmp_path: Path) -> None:
    address = f"127.0.0.1:{free_port()}"  # nothing listens there
    for args in (
        ["reproduce", "--address", address],
        ["tune", "--address", address],
        ["ablation", "--address", address],
    ):
        proc = subprocess.run(
            command(*args, "--out", str(tmp_path / "x"), "--quiet"),
            capture_output=True,
            text=True,
            timeout=HANG,
            env=clean_env(),
        )
        assert proc.returncode == 2, proc.stderr
        assert f"cannot reach a Ray cluster at {address}" in proc.stderr
        assert "Traceback" not in proc.stderr
    with pytest.raises(ValueError, match="HOST:PORT"):
        cluster.check_reachable("no-port-here")
    env = {**clean_env(), "RAY_ADDRESS": address}  # the variable is honoured like --address
    proc = subprocess.run(
        command("reproduce", "--out", str(tmp_path / "y"), "--quiet"),
        capture_output=True,
        text=True,
        timeout=HANG,
        env=env,
    )
    assert proc.returncode == 2 and "cannot reach a Ray cluster" in proc.stderr


def _wait_for(path: Path, proc: subprocess.Popen[str]) -> None:
    deadline = time.monotonic() + HANG
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the first run never arrived"
        time.sleep(0.1)


def _two_jobs(out: Path) -> list[str]:
    # One CPU: the two runs go one after the other; 40 updates keep the second one running
    # for a while after the first arrived.
    return command(
        "reproduce",
        "--configs",
        "rl_cbf",
        "--seeds",
        "0",
        "1",
        "--updates",
        "40",
        "--trials",
        "3",
        "--workers",
        "1",
        "--out",
        str(out),
        "--quiet",
    )


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _first_of_two_jobs(out: Path) -> tuple[subprocess.Popen[str], Path]:
    """Starts the two-job reproduce; returns once the first run has arrived in ``out``."""
    proc = subprocess.Popen(
        _two_jobs(out),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=clean_env(),
        # SIGINT as a shell leaves it: in a full pytest run the command once ignored Ctrl-C
        # (an ignored SIGINT is inherited; which earlier test leaves it so was not found).
        preexec_fn=_default_sigint,
    )
    first = out / "rl_cbf_s0" / "evaluation.json"
    _wait_for(first, proc)
    return proc, first


def test_an_interrupted_reproduce_resumes_keeping_finished_runs(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc, first = _first_of_two_jobs(out)
    proc.send_signal(signal.SIGINT)  # Ctrl-C while the second run trains
    _, err = proc.communicate(timeout=HANG)
    assert proc.returncode == 130, err
    assert "interrupted" in err
    assert not (out / "rl_cbf_s1").exists()  # no half-written run
    kept = first.stat().st_mtime_ns
    proc2 = subprocess.run(
        _two_jobs(out), capture_output=True, text=True, timeout=HANG, env=clean_env()
    )
    assert proc2.returncode == 0, proc2.stderr
    assert first.stat().st_mtime_ns == kept  # the finished run was skipped, not redone
    assert (out / "rl_cbf_s1" / "evaluation.json").is_file()
    assert "| rl_cbf | 0, 1 | 40 |" in proc2.stdout


def _task_workers(root: int) -> list[int]:
    """The Ray task workers of the run started as process ``root`` (its local Ray's raylet is
    its child, the workers the raylet's): never another Ray's on the same machine."""
    ps = subprocess.run(["ps", "-eo", "pid,ppid,args"], capture_output=True, text=True).stdout
    rows = [line.split(None, 2) for line in ps.splitlines()[1:]]
    parent = {int(r[0]): int(r[1]) for r in rows}

    def under_root(pid: int) -> bool:
        while pid > 1:
            if pid == root:
                return True
            pid = parent.get(pid, 1)
        return False

    return [
        int(r[0])
        for r in rows
        if len(r) == 3 and "ray::run_in_tempdir" in r[2] and under_root(int(r[0]))
    ]


def test_a_worker_that_dies_is_retried_without_losing_finished_runs(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc, first = _first_of_two_jobs(out)
    kept = first.stat().st_mtime_ns
    deadline = time.monotonic() + HANG
    while not (pids := _task_workers(proc.pid)):  # the worker that trains the second run
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    for pid in pids:
        os.kill(pid, signal.SIGKILL)
    _, err = proc.communicate(timeout=HANG)
    assert proc.returncode == 0, err
    assert first.stat().st_mtime_ns == kept
    second = json.loads((out / "rl_cbf_s1" / "evaluation.json").read_text())
    assert second["trials"] == 3


@pytest.fixture(params=["token", "disabled"])
def ray_cluster(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[str, dict]]:
    """A real Ray cluster of this machine (`ray start --head` on 127.0.0.1), with and without
    token authentication, stopped after; yields its address and the environment a client
    gets (the token's path, not RAY_AUTH_MODE: tlshield must send the token by itself)."""
    port = free_port()
    client = {k: v for k, v in clean_env().items() if k != "RAY_AUTH_MODE"}
    if request.param == "token":
        token = tmp_path / "auth_token"
        token.write_text(os.urandom(32).hex())
        client["RAY_AUTH_TOKEN_PATH"] = str(token)
    head_env = {**client, "RAY_AUTH_MODE": request.param}
    head = subprocess.Popen(
        [
            RAY,
            "start",
            "--head",
            "--node-ip-address=127.0.0.1",
            f"--port={port}",
            "--num-cpus=2",
            "--include-dashboard=false",
            "--disable-usage-stats",
            "--block",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env=head_env,
    )
    address = f"127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + HANG
        while True:
            status = subprocess.run(
                [RAY, "status", "--address", address],
                capture_output=True,
                text=True,
                env=head_env,
            )
            if status.returncode == 0 and "CPU" in status.stdout:
                break
            assert head.poll() is None, "ray start --head exited"
            assert time.monotonic() < deadline, "the cluster never came up"
            time.sleep(1)
        yield address, client
    finally:
        # `ray start --block` shuts its processes down on SIGTERM but then lingers about 30 s;
        # past a short grace the whole group (the head's processes) is killed.
        os.killpg(head.pid, signal.SIGTERM)
        try:
            head.wait(timeout=5)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait(timeout=HANG)


def test_reproduce_on_a_cluster_through_its_address(
    ray_cluster: tuple[str, dict], tmp_path: Path
) -> None:
    address, env = ray_cluster
    out = tmp_path / "out"
    args = ["--configs", "rl_cbf_clf", "--seeds", "0", "1", "--updates", "2", "--trials", "3"]
    proc = subprocess.run(
        command("reproduce", *args, "--address", address, "--out", str(out), "--quiet"),
        capture_output=True,
        text=True,
        timeout=HANG,
        env=env,
    )
    assert proc.returncode == 0, proc.stderr
    for seed in (0, 1):
        run = out / f"rl_cbf_clf_s{seed}"
        assert (run / "evaluation.json").is_file() and (run / "model.zip").is_file()
    assert "| rl_cbf_clf | 0, 1 | 2 |" in proc.stdout


def test_a_two_sample_tune_writes_settings_that_train_reads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from tlshield.lab.tune import DEFAULTS, searchable, tune

    root = tune(tmp_path / "tune", samples=2, updates=3, trials=2, workers=2, progress=False)
    with (root / "trials.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2 and {r["trial"] for r in rows} == {"0", "1"}
    assert set(searchable("rl_cbf_clf")) <= set(rows[0])
    assert (root / "trials.md").is_file() and (root / "trials.png").stat().st_size > 0
    best = json.loads((root / "best.json").read_text())
    assert best["config"] == "rl_cbf_clf" and 0.0 <= best["objective"] <= 1.0
    # The first sample is the defaults: a default sample maps back to the default settings.
    from tlshield.envs.channel import ChannelParams
    from tlshield.lab.tune import to_settings

    as_settings = to_settings(dict(DEFAULTS), "rl_cbf_clf")
    cfg = ChannelParams()
    assert as_settings["clf_bounds"] == [list(b) for b in cfg.shield.clf_bounds]
    assert as_settings["cbf_bounds"] == [list(b) for b in cfg.shield.cbf_bounds]
    # Run again with the same arguments, the finished search is restored, not redone; with
    # other arguments it is refused.
    again = tune(tmp_path / "tune", samples=2, updates=3, trials=2, workers=2, progress=False)
    assert json.loads((again / "best.json").read_text())["settings"] == best["settings"]
    with pytest.raises(ValueError, match="holds a search with other arguments"):
        tune(tmp_path / "tune", samples=3, updates=3, trials=2, workers=2, progress=False)
    # best.json is what train --settings reads, and the run uses every setting in it.
    run = tmp_path / "trained"
    code = cli.main(
        [
            "train",
            "--settings",
            str(root / "best.json"),
            "--updates",
            "1",
            "--out",
            str(run),
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    record = json.loads((run / "run.json").read_text())
    assert record["config"] == "rl_cbf_clf"
    for name, value in best["settings"].items():
        if name in settings.PPO_NAMES:
            assert record["ppo"][name] == value, name
        elif name in settings.SCHEDULE_NAMES:
            assert record[name] == value, name
        else:
            assert json.loads(json.dumps(record["env"][name])) == value, name


def test_unknown_settings_are_rejected_with_the_known_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "best.json"
    bad.write_text(json.dumps({"config": "rl_cbf", "settings": {"alpha": 3.0, "alfa": 3.0}}))
    out = str(tmp_path / "r")
    assert cli.main(["train", "--settings", str(bad), "--out", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "unknown setting(s) alfa" in err and "known: " in err and "learning_rate" in err
    assert cli.main(["train", "--set", "learnin_rate=1e-3", "--out", out, "--quiet"]) == 2
    assert "--set: unknown setting(s) learnin_rate" in capsys.readouterr().err
    assert cli.main(["train", "--set", "alpha", "--out", out, "--quiet"]) == 2
    assert "expected NAME=VALUE" in capsys.readouterr().err
    assert cli.main(["train", "--set", "alpha=50", "--out", out, "--quiet"]) == 2
    assert "alpha * dt" in capsys.readouterr().err  # a bad value, where it is given
    assert cli.main(["tune", "--search", "alpha", "K_", "--out", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "K_" in err and "searchable: c_r, w, alpha" in err
    assert cli.main(["tune", "--config", "rl", "--search", "alpha", "--out", out]) == 2
    assert "not searchable for rl" in capsys.readouterr().err  # rl has no CBF to tune
    assert not (tmp_path / "r").exists()  # nothing was started
    with pytest.raises(ValueError, match="not JSON"):
        (tmp_path / "junk.json").write_text("{")
        settings.load(tmp_path / "junk.json")


def test_set_on_the_command_line_reaches_the_run(tmp_path: Path) -> None:
    run = tmp_path / "r"
    args = ["train", "--config", "rl_cbf", "--updates", "1", "--out", str(run), "--quiet"]
    sets = ["--set", "alpha=3", "--set", "learning_rate=0.001", "--set", "clf_schedule=linear"]
    assert cli.main([*args, *sets]) == 0
    record = json.loads((run / "run.json").read_text())
    assert record["env"]["alpha"] == 3 and record["ppo"]["learning_rate"] == 0.001
    assert record["clf_schedule"] == "linear"


def test_a_shield_put_in_ray_filters_like_the_local_one() -> None:
    """``ray.put(shield)`` and a Ray task that filters with it give the local shield's actions
    (the shield travels as data: its spec's text and numbers, its model and parameters)."""
    import numpy as np
    import ray

    from tests.fixtures import task_shield

    shield = task_shield()
    rng = np.random.default_rng(0)
    states = np.zeros((20, 13))
    states[:, :3] = rng.uniform(-1.0, 1.0, size=(20, 3))
    states[:, 3:9] = [4.0, 4.0, 4.5, 6.5, 9.0, 9.0]
    states[:, 9:13] = [20.0, 20.0, 20.0, -20.0]
    qs = shield.automaton.step_batch(states, np.zeros(20, dtype=int))
    a_rl = rng.uniform(-1.0, 1.0, size=(20, 2))
    local = shield.filter_batch(states, qs, a_rl).action

    def remote_filter(shield, states, qs, a_rl):  # type: ignore[no-untyped-def]
        return np.stack(
            [shield.filter(s, int(q), a).action for s, q, a in zip(states, qs, a_rl, strict=True)]
        )

    ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        ref = ray.put(shield)
        assert ray.get(ref).filter(states[0], int(qs[0]), a_rl[0]).action.tolist() == (
            local[0].tolist()
        )
        task = ray.remote(remote_filter)
        remote = ray.get(task.remote(ref, states, qs, a_rl), timeout=HANG)
    finally:
        ray.shutdown()
    assert remote.tobytes() == local.tobytes()
