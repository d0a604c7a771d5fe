"""Contacts and give-ways of trained policies: evaluates every shielded run of a results folder
(``tlshield reproduce``'s) on ``--trials`` trials, kept and last policy, on copies of the run
folders (their own evaluation.json stays as it is), and prints one row per policy: success, the
trials that touched an obstacle, contacts on steps where no barrier gave way (unreported), the
evaluation's give-ways by barrier, trials that touched and still counted as a success, and the
training's give-ways by barrier (run.json).

``python scripts/contacts.py results --trials 500``
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

from tlshield.lab.evaluation import evaluate


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("--trials", type=int, default=500)
    args = parser.parse_args(argv)
    print(
        "| config | seed | policy | success | trials that touched | unreported contacts "
        "| touched and counted a success | give-ways in evaluation | give-ways in training |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---|---|")
    for run in sorted(args.results.iterdir()):
        if not (run / "run.json").is_file():
            continue
        record = json.loads((run / "run.json").read_text())
        if record["config"] not in ("rl_cbf", "rl_cbf_clf"):
            continue
        for which in ("kept", "last"):
            with tempfile.TemporaryDirectory() as tmp:
                copy = Path(tmp) / run.name
                shutil.copytree(run, copy)
                r = evaluate(copy, trials=args.trials, which=which)
            touched = sum(bool(o["success"]) and bool(o["collision"]) for o in r["outcomes"])
            print(
                f"| {record['config']} | {record['seed']} | {which} | {r['success_rate']:.3f} "
                f"| {r['collisions']} | {r['unreported_contacts']} | {touched} "
                f"| {r['gave_way']} | {record.get('gave_way')} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
