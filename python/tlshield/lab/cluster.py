"""Ray for tlshield's sweeps: connecting (an embedded local Ray by default, an existing cluster
by address) and running folder-writing jobs as Ray tasks whose folders come back to the
machine that started the command.

Each job is a picklable callable that writes one run into the folder it is given. On the
worker it writes into a temporary folder; the folder travels back packed (tar + gzip) as the
task's result and is unpacked under the output folder of the driver, whichever node ran it.
A run appears in the output folder only once it finished, so an interrupted sweep leaves no
half-written runs behind and resumes by skipping the folders present. A worker that dies is
retried by Ray (``max_retries``); runs already gathered stay.
"""

from __future__ import annotations

import io
import logging
import os
import shutil
import socket
import tarfile
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

#: Times Ray re-runs a job whose worker process or node died.
MAX_RETRIES = 3
#: Seconds to wait for a TCP connection to a cluster's address before calling it unreachable.
CONNECT_TIMEOUT = 5.0
#: A job: writes one run into the folder it is called with.
Job = Callable[[Path], Any]


def resolve_address(address: str | None) -> str | None:
    """The cluster to use: ``address``, else ``RAY_ADDRESS``, else ``None`` (a local Ray)."""
    address = address or os.environ.get("RAY_ADDRESS") or None
    return None if address in (None, "local") else address


def check_reachable(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """Raises ConnectionError within ``timeout`` seconds when nothing listens at ``address``
    (``host:port`` or ``ray://host:port``; ``auto`` is left to Ray, which fails fast), instead
    of letting ``ray.init`` retry for minutes."""
    if address == "auto":
        return
    hostport = address.split("://", 1)[-1]
    host, sep, port = hostport.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ValueError(f"Ray address {address!r}: expected HOST:PORT (e.g. 127.0.0.1:6379)")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as err:
        raise ConnectionError(
            f"cannot reach a Ray cluster at {address} ({err.strerror or err}); start one with "
            "`ray start --head`, or leave out --address to run on a local Ray"
        ) from None


@contextmanager
def session(address: str | None = None, workers: int | None = None) -> Iterator[str]:
    """Ray for the duration of the block: a local Ray with ``workers`` CPUs (all cores by
    default) started inside this process and stopped after it, or the cluster at ``address`` /
    ``RAY_ADDRESS`` (checked to be reachable first). Yields a description of where it runs."""
    import ray

    if workers is not None and not (isinstance(workers, int) and workers > 0):
        raise ValueError(f"workers = {workers!r}: expected a positive integer")
    address = resolve_address(address)
    if address is not None:
        check_reachable(address)
    if ray.is_initialized():  # the caller's own Ray (e.g. in a notebook): used as it is
        yield "the Ray this process already runs"
        return
    quiet: dict[str, Any] = {"logging_level": logging.ERROR, "log_to_driver": False}
    if address is None:
        ray.init(address="local", num_cpus=workers, include_dashboard=False, **quiet)
        where = f"a local Ray with {int(ray.cluster_resources().get('CPU', 0))} CPUs"
    else:
        _connect(address, **quiet)
        where = f"the Ray cluster at {address}"
    try:
        yield where
    finally:
        ray.shutdown()


def _connect(address: str, **options: Any) -> None:
    """``ray.init`` at ``address``. Ray >= 2.5x: ``ray start --head`` turns token
    authentication on when its machine has a token, and a driver then needs
    ``RAY_AUTH_MODE=token`` (a token-less cluster must not get it: its nodes then fail to hand
    results over). Unless the mode is set, connect without; if refused and this machine has a
    token (``RAY_AUTH_TOKEN``, ``RAY_AUTH_TOKEN_PATH``, ``~/.ray/auth_token``), with it."""
    import ray

    try:
        ray.init(address=address, **options)
        return
    except ConnectionError as err:
        path = os.environ.get("RAY_AUTH_TOKEN_PATH") or str(Path.home() / ".ray" / "auth_token")
        has_token = bool(os.environ.get("RAY_AUTH_TOKEN")) or Path(path).is_file()
        if "RAY_AUTH_MODE" in os.environ or not has_token:
            raise ConnectionError(
                f"{err} (a cluster with token authentication, Ray's default for `ray start "
                "--head` on a machine with a token, needs the same token here: RAY_AUTH_TOKEN, "
                "RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token)"
            ) from None
    ray.shutdown()
    os.environ["RAY_AUTH_MODE"] = "token"  # what Ray's own `ray start` does with a token
    from ray._raylet import Config

    Config.initialize("")
    ray.init(address=address, **options)


def run(
    jobs: dict[Path, Job],
    *,
    on_done: Callable[[Path], None] | None = None,
) -> None:
    """Runs each job as a Ray task (one CPU each, so as many at a time as the cluster has
    CPUs) inside a :func:`session` and unpacks its folder at its key. ``on_done`` is called
    with each folder as it arrives. Jobs that fail are reported together after the others
    finished (their folders are not written)."""
    import ray

    task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(run_in_tempdir)
    pending = {task.remote(job, folder.name): folder for folder, job in jobs.items()}
    failures: list[str] = []
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            folder = pending.pop(ready[0])
            try:
                unpack(ray.get(ready[0]), folder)
            except ray.exceptions.RayError as err:
                failures.append(f"{folder}: {_cause(err)}")
                continue
            if on_done is not None:
                on_done(folder)
    finally:
        for ref in pending:  # interrupted: do not leave jobs running on a cluster
            ray.cancel(ref, force=True)
    if failures:
        raise RuntimeError(f"{len(failures)} run(s) failed on Ray:\n" + "\n".join(failures))


def run_counted(
    jobs: dict[Path, Job],
    address: str | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> None:
    """:func:`run` inside a :func:`session`, with a progress bar of runs (on stderr, when
    ``progress``) that names the last one gathered: the one dispatch loop of every sweep
    (reproduction, ablation, benchmarks). Nothing to do when ``jobs`` is empty."""
    if not jobs:
        return
    from tqdm.auto import tqdm

    bar = tqdm(total=len(jobs), desc="runs", unit="run", disable=not progress, leave=False)

    def tick(folder: Path) -> None:
        bar.update(1)
        bar.set_postfix_str(folder.name)

    try:
        with session(address, workers):
            run(jobs, on_done=tick)
    finally:
        bar.close()


def run_in_tempdir(job: Job, name: str) -> bytes:
    """Runs ``job`` on a folder ``name`` in a temporary directory and returns it packed (the
    body of the Ray task)."""
    with tempfile.TemporaryDirectory(prefix="tlshield-") as tmp:
        folder = Path(tmp, name)
        job(folder)
        return pack(folder)


def pack(folder: Path) -> bytes:
    """``folder`` as gzip'd tar bytes (its contents, relative to it)."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz", compresslevel=1) as tar:
        tar.add(folder, arcname=".")
    return buffer.getvalue()


def unpack(data: bytes, folder: Path) -> None:
    """Writes packed ``data`` as ``folder``, replacing what was there only once the whole
    folder is unpacked beside it."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    incoming = folder.with_name(f".{folder.name}.incoming")
    shutil.rmtree(incoming, ignore_errors=True)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        if hasattr(tarfile, "data_filter"):  # Python >= 3.10.12: refuse links out of folder
            tar.extractall(incoming, filter="data")
        else:
            tar.extractall(incoming)
    if folder.exists():
        shutil.rmtree(folder)
    incoming.rename(folder)


def _cause(err: Exception) -> str:
    cause = getattr(err, "cause", None)
    return f"{type(cause).__name__}: {cause}" if cause is not None else str(err).splitlines()[0]
