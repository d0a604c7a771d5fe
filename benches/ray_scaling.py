"""How the wall time of a 16-job ``tlshield reproduce`` falls with the number of Ray worker
nodes, on a multi-node Ray cluster built on this machine.

For each size W, a head node without CPUs (``ray start --head --num-cpus 0``) and W worker
nodes of one CPU each (``ray start --address HEAD --num-cpus 1``), all on 127.0.0.1, each its
own raylet as on separate machines; ``tlshield reproduce --address HEAD`` then runs the
(configuration x seed) jobs as tasks on the workers and gathers the run folders on the driver.
The cluster is stopped between sizes. On paper the jobs are independent, so the wall time is
about ceil(jobs / W) x (one job) plus the driver's fixed costs (connecting, the figures and the
table); on this 2-core machine the workers beyond 2 share the cores, so the time should stop
falling at W = 2. The runs must be identical at every size (metrics without wall times), else
exit 1.

Run: ``.venv/bin/python benches/ray_scaling.py [--workers 1 2 3 4] [--updates 20] [--quick]``.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

RAY = str(Path(sys.executable).parent / "ray")
#: The ports of a node, each given a free one.
NODE_PORTS = (
    "node-manager",
    "object-manager",
    "dashboard-agent-listen",
    "dashboard-agent-grpc",
    "metrics-export",
    "runtime-env-agent",
)
#: Object store per node (bytes): the runs travel as a few hundred kB each.
OBJECT_STORE = 100 * 1024 * 1024


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


#: The throwaway loopback cluster runs without token authentication (Ray turns it on when the
#: machine has a token; the nodes joining would then need it too).
NODE_ENV = {**os.environ, "RAY_AUTH_MODE": "disabled"}


def _start(args: list[str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [RAY, "start", *args, "--block", "--disable-usage-stats"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env=NODE_ENV,
    )


def _wait_for_cpus(address: str, cpus: int, node: subprocess.Popen[bytes]) -> bool:
    """Waits until the cluster has ``cpus`` CPUs (True), or until the node that should bring
    the last one has exited (False: on a loaded machine a joining raylet can time out
    registering with the head and quit)."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        status = subprocess.run(
            [RAY, "status", "--address", address], capture_output=True, text=True, env=NODE_ENV
        ).stdout
        if f"/{float(cpus)} CPU" in status:
            return True
        if node.poll() is not None:
            return False
        time.sleep(1)
    raise RuntimeError(f"the cluster at {address} never reached {cpus} CPUs")


#: Tries per worker node: a node that quit while joining is started again (fresh ports).
NODE_TRIES = 3


def with_cluster(workers: int, run: list[str]) -> float:
    """Starts a head and ``workers`` one-CPU worker nodes, times ``run`` + ``--address``."""
    port = _free_port()
    address = f"127.0.0.1:{port}"
    common = ["--node-ip-address=127.0.0.1", f"--object-store-memory={OBJECT_STORE}"]
    nodes = [
        _start(["--head", f"--port={port}", "--num-cpus=0", "--include-dashboard=false", *common])
    ]
    try:
        time.sleep(3)
        for k in range(workers):
            # Nodes sharing a machine need their own ports (the defaults would collide and
            # the later raylet dies), and start one at a time (started together, one timed
            # out registering with the head).
            for _ in range(NODE_TRIES):
                ports = [f"--{name}-port={_free_port()}" for name in NODE_PORTS]
                nodes.append(_start([f"--address={address}", "--num-cpus=1", *ports, *common]))
                if _wait_for_cpus(address, k + 1, nodes[-1]):
                    break
            else:
                raise RuntimeError(f"no worker node joined {address} in {NODE_TRIES} tries")
        # The driver finds the cluster by --address and decides on a token itself.
        env = {k: v for k, v in os.environ.items() if k not in ("RAY_ADDRESS", "RAY_AUTH_MODE")}
        start = time.perf_counter()
        subprocess.run([*run, "--address", address], check=True, env=env, stdout=subprocess.DEVNULL)
        return time.perf_counter() - start
    finally:
        for node in reversed(nodes):
            with contextlib.suppress(ProcessLookupError):  # a node that quit while joining
                os.killpg(node.pid, signal.SIGTERM)
            node.wait(timeout=120)


def metrics(run: Path) -> list[dict[str, str]]:
    with (run / "metrics.csv").open() as f:
        return [{k: v for k, v in r.items() if k != "wall_time"} for r in csv.DictReader(f)]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", nargs="+", type=int, default=[1, 2, 3, 4])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3])
    parser.add_argument("--updates", type=int, default=20)
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--quick", action="store_true", help="W = 1, 2; 2 jobs of 1 update")
    args = parser.parse_args(argv)
    configs = ["rl", "rl_cbf", "rl_clf", "rl_cbf_clf"]
    if args.quick:
        args.workers, args.seeds, args.updates, args.trials, configs = (
            [1, 2],
            [0],
            1,
            2,
            ["rl", "rl_cbf_clf"],
        )
    n_jobs = len(configs) * len(args.seeds)
    print(
        f"{n_jobs} jobs ({', '.join(configs)} x seeds {args.seeds}), {args.updates} updates and "
        f"{args.trials} evaluation trials each; {os.cpu_count()} cores"
    )
    scratch = Path(tempfile.mkdtemp(prefix="ray-scaling-"))
    rows = []
    try:
        for w in args.workers:
            out = scratch / f"w{w}"
            run = [
                sys.executable,
                "-m",
                "tlshield",
                "reproduce",
                "--out",
                str(out),
                "--configs",
                *configs,
                "--seeds",
                *map(str, args.seeds),
                "--updates",
                str(args.updates),
                "--trials",
                str(args.trials),
                "--quiet",
            ]
            wall = with_cluster(w, run)
            rows.append((w, wall))
            print(f"{w} worker node(s): {wall:.1f} s", flush=True)
            first = scratch / f"w{args.workers[0]}"
            for folder in sorted(out.glob("*_s*")):
                if metrics(folder) != metrics(first / folder.name):
                    print(f"FAIL: {folder.name} differs between cluster sizes")
                    return 1
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    # On paper, from the first size's time per job: W workers take ceil(jobs / W) job times;
    # on this machine at most its cores run at once.
    per_job = rows[0][1] / math.ceil(n_jobs / rows[0][0])
    cores = os.cpu_count() or 1
    print()
    print(
        f"| worker nodes (1 CPU each) | wall time | speedup vs {rows[0][0]} | on paper | "
        f"on paper, {cores} cores |"
    )
    print("|---:|---:|---:|---:|---:|")
    for w, wall in rows:
        paper = math.ceil(n_jobs / w) * per_job
        capped = math.ceil(n_jobs / min(w, cores)) * per_job
        print(f"| {w} | {wall:.1f} s | {rows[0][1] / wall:.2f} | {paper:.1f} s | {capped:.1f} s |")
    print(f"runs identical at every size: yes ({n_jobs} jobs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
