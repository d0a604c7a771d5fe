"""The ``tlshield`` command line."""

from __future__ import annotations

import argparse
import itertools
import os
import shutil
import subprocess
import sys
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import error as gym_error

from tlshield._core import Automaton, SpecError
from tlshield.envs import ENV_ID, FLATWORLD_ID, POINT_MASS_ID
from tlshield.envs.channel import STATE_DIM, TASK, channel_task_spec
from tlshield.envs.params import FULL
from tlshield.envs.profile import profile_of
from tlshield.envs.safety_gym import MissingStack
from tlshield.lab.envs import import_modules
from tlshield.lab.presets import DEFAULT_TRIALS, DEFAULT_UPDATES, STUDY_UPDATES

#: Top-level modules of the ``train`` extra (pyproject.toml), for a clear message when missing.
TRAINING_MODULES = frozenset(
    {"stable_baselines3", "torch", "matplotlib", "tensorboard", "tqdm", "rich", "ray", "optuna"}
)


def _straight_path(waypoints: Sequence[tuple[float, float]], steps_per_leg: int) -> np.ndarray:
    points = [np.asarray(waypoints[0], dtype=float)]
    for a, b in itertools.pairwise(waypoints):
        for k in range(1, steps_per_leg + 1):
            points.append(np.asarray(a) + (np.asarray(b) - np.asarray(a)) * k / steps_per_leg)
    return np.array(points)


def _demo(args: argparse.Namespace) -> int:
    if args.steps < 2:
        print("tlshield demo: error: --steps must be at least 2", file=sys.stderr)
        return 2
    spec = channel_task_spec(half_width=args.half_width, goal_radius=args.goal_radius)
    goals = np.array([[1.0, 2.0], [3.0, 1.0], [5.0, 5.2]])
    obstacles = np.array([[1.0, 3.0], [4.0, 2.0]])
    scene = np.concatenate([goals.ravel(), obstacles.ravel()])

    def trajectory(waypoints: Sequence[tuple[float, float]]) -> np.ndarray:
        xy = _straight_path(waypoints, steps_per_leg=args.steps // (len(waypoints) - 1))
        traj = np.zeros((len(xy), STATE_DIM))
        traj[:, :2] = xy
        traj[:, 3:] = scene
        return traj

    cases = {
        "g1 then g3, inside the channel": trajectory([(0.0, 0.0), (1.0, 2.0), (5.0, 5.2)]),
        "g3 first (violates !g3 U (g1|g2))": trajectory([(0.0, 0.0), (5.0, 5.2), (1.0, 2.0)]),
        "leaves the channel on the way": trajectory([(0.0, 0.0), (2.5, 0.0), (1.0, 2.0), (5, 5.2)]),
        "never reaches a goal": trajectory([(0.0, 0.0), (1.0, 1.0)]),
    }
    print(f"task: {spec}")
    print(f"atoms: {', '.join(spec.atoms)}")
    print(f"{'trajectory':<40} {'steps':>6} {'robustness':>11} satisfied")
    for name, traj in cases.items():
        rho = spec.robustness(traj)
        print(f"{name:<40} {len(traj) - 1:>6} {rho:>11.4f} {spec.satisfied(traj)}")
    batch = np.stack([cases["g1 then g3, inside the channel"]] * 4)
    print(f"batch of {len(batch)}: {spec.robustness_batch(batch)}")
    return 0


def _fsa(args: argparse.Namespace) -> int:
    try:
        aut = Automaton.from_formula(args.formula)
    except SpecError as err:
        print(f"tlshield fsa: {err}", file=sys.stderr)
        return 2
    roles = {aut.initial: "initial"}
    for q in aut.accepting:
        roles[q] = "accepting"
    if aut.trap is not None:
        roles[aut.trap] = "trap"
    print(f"formula: {aut.spec}")
    print(f"atoms:   {', '.join(aut.atoms)}")
    print(f"states:  {aut.num_states}")
    for q in range(aut.num_states):
        tags = [roles[q]] if q in roles else []
        if aut.initial == q and roles.get(q) != "initial":
            tags.insert(0, "initial")
        print(f"  q{q}{' (' + ', '.join(tags) + ')' if tags else ''}")
        for src, dst, guard in aut.edges():
            if src == q:
                print(f"    -> q{dst}: {guard}")
        clauses = aut.trap_cnf(q)
        if clauses:
            text = " & ".join("(" + " | ".join(clause) + ")" for clause in clauses)
            print(f"    safe set (CNF of the negated trap guard): {text}")
    if args.dot or args.png:
        dot = aut.to_dot()
        if args.dot:
            Path(args.dot).write_text(dot)
            print(f"wrote {args.dot}")
        if args.png:
            graphviz = shutil.which("dot")
            if graphviz is None:
                print(
                    "tlshield fsa: graphviz `dot` not found; install graphviz for --png",
                    file=sys.stderr,
                )
                return 1
            subprocess.run([graphviz, "-Tpng", "-o", args.png], input=dot, text=True, check=True)
            print(f"wrote {args.png}")
    return 0


def _positive(text: str) -> int:
    value = int(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text}")
    return value


def _settings(args: argparse.Namespace, env_id: str = ENV_ID) -> dict[str, object]:
    """``--settings FILE`` then ``--set NAME=VALUE`` (later wins) as :func:`train` keywords,
    over the preset's and the schedule options'; fills ``args.config`` from the file when the
    command line names none."""
    from tlshield.lab import settings

    chosen: dict[str, object] = {}
    named = None
    if args.settings:
        chosen, named = settings.load(args.settings)
    chosen.update(settings.parse_assignments(args.set or [], env_id))
    if getattr(args, "config", "") is None:
        args.config = named or FULL
    return {
        "clf_schedule": args.clf_schedule,
        "clf_final_scale": args.clf_final_scale,
        **_preset_options(args),  # the preset's environment; it sets no PPO keywords
        **settings.split(chosen, env_id),
    }


def _train(args: argparse.Namespace) -> int:
    from tlshield.lab.training import train

    import_modules(args.imports)  # before --set is read against the env's parameters
    options = _settings(args, args.env)
    run = train(
        args.config,
        args.seed,
        args.updates,
        args.out,
        env=args.env,
        progress=not args.quiet,
        imports=args.imports,
        **options,  # type: ignore[arg-type]
    )
    print(f"wrote {run} (metrics.csv, model.zip, tb/, run.json)")
    if args.evaluate:
        _print_evaluation(_evaluate_run(run, args.trials))
    return 0


def _evaluate_run(
    run: Path | str, trials: int, which: str = "kept", trust_pickles: bool = False
) -> dict[str, object]:
    from tlshield.lab.evaluation import evaluate

    if not Path(run).is_dir():
        what = "not a folder" if Path(run).exists() else "no such folder"
        raise FileNotFoundError(f"{run}: {what}, so not a tlshield run folder")
    return evaluate(run, trials=trials, which=which, trust_pickles=trust_pickles)


def _print_evaluation(result: dict[str, object]) -> None:
    from tlshield.lab.measures import shown

    collisions, steps = result["collisions"], result["violation_steps"]
    print(
        f"{result['config']} seed {result['seed']} ({result.get('policy', 'kept')} policy): "
        f"success {result['successes']}/"
        f"{result['trials']} ({result['success_rate']:.0%}), "
        f"collisions {shown(collisions)}, "  # type: ignore[arg-type]
        f"violation steps {shown(steps)}"  # type: ignore[arg-type]
        + (
            f", return {result['return_mean']:.2f}, cost {result['cost_mean']:.1f} per episode"
            if result.get("cost_mean") is not None
            else ""
        )
    )


def _evaluate(args: argparse.Namespace) -> int:
    import_modules(args.imports)
    for run in args.runs:
        _print_evaluation(_evaluate_run(run, args.trials, args.policy, args.trust_pickles))
    return 0


def _reproduce(args: argparse.Namespace) -> int:
    from tlshield.lab.training import reproduce

    root = reproduce(
        args.out,
        configs=tuple(args.configs),
        seeds=tuple(args.seeds),
        updates=args.updates,
        trials=args.trials,
        **_ray_options(args),
        **_settings(args),  # type: ignore[arg-type]
    )
    print((root / "results.md").read_text())
    print(f"figures in {root / 'figures'}")
    return 0


def _ray_options(args: argparse.Namespace) -> dict[str, Any]:
    """What every sweep command passes on about Ray and its progress bar."""
    return {"workers": args.workers, "address": args.address, "progress": not args.quiet}


def _ablation(args: argparse.Namespace) -> int:
    from tlshield.lab.training import ablation

    root = ablation(
        args.out,
        seeds=tuple(args.seeds),
        updates=args.updates,
        trials=args.trials,
        **_ray_options(args),
    )
    print((root / "ablation.md").read_text())
    return 0


def _tune(args: argparse.Namespace) -> int:
    from tlshield.lab.tune import tune

    root = tune(
        args.out,
        config=args.config,
        samples=args.samples,
        updates=args.updates,
        search=args.search,
        seed=args.seed,
        trials=args.trials,
        **_ray_options(args),
    )
    print((root / "trials.md").read_text())
    print((root / "best.json").read_text())
    print(f"wrote {root / 'best.json'} (use: tlshield train --settings {root / 'best.json'})")
    return 0


def _plot(args: argparse.Namespace) -> int:
    from tlshield.lab.plots import plot_all
    from tlshield.lab.report import results_table, seeds_table

    for path in plot_all(args.results, args.out):
        print(f"wrote {path}")
    print(results_table(args.results))
    print()
    print(seeds_table(args.results))
    return 0


def _preset_options(args: argparse.Namespace) -> dict[str, object]:
    """``--preset NAME`` trains with that preset's PPO settings and the env settings the env's
    profile says it implies (``--preset paper`` on Channel-v0: the paper's environment, Eq. 5A1
    reward, 13-value observation, no moving-obstacle barrier)."""
    implied = profile_of(getattr(args, "env", ENV_ID)).preset_overrides.get(args.preset, {})
    return {"preset": args.preset, **implied}


def _add_preset(parser: argparse.ArgumentParser) -> None:
    from tlshield.lab.presets import PRESETS

    parser.add_argument(
        "--preset",
        choices=tuple(PRESETS),
        default="default",
        help="default: tlshield's settings (docs/reproduction.md, the ablation); paper: the "
        "paper's PPO, reward, observation and obstacles; flatworld: the FlatWorld benchmark's "
        "PPO",
    )


def _add_schedule(parser: argparse.ArgumentParser) -> None:
    from tlshield.lab.presets import DEFAULT_FINAL_SCALE, DEFAULT_SCHEDULE, SCHEDULES

    parser.add_argument(
        "--clf-schedule",
        choices=SCHEDULES,
        default=DEFAULT_SCHEDULE,
        help=f"shrink the CLF bounds as training progresses (default: {DEFAULT_SCHEDULE})",
    )
    parser.add_argument(
        "--clf-final-scale",
        type=float,
        default=DEFAULT_FINAL_SCALE,
        help="CLF bound scale at the end of training for a shrinking schedule "
        f"(default {DEFAULT_FINAL_SCALE})",
    )


def _add_settings(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--settings",
        metavar="FILE",
        help="JSON settings, e.g. the best.json of tlshield tune (names: tlshield.lab.settings)",
    )
    parser.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="one setting (JSON value), e.g. --set alpha=3 --set learning_rate=1e-3",
    )


def _add_ray(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--workers",
        type=_positive,
        default=None,
        help="CPUs of the local Ray (default: all cores); ignored with --address",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="an existing Ray cluster (HOST:PORT of `ray start --head`; default: $RAY_ADDRESS, "
        "else a local Ray started inside the command)",
    )


def _add_import(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--import",
        dest="imports",
        action="append",
        default=[],
        metavar="MODULE",
        help="import MODULE first, where your environment registers itself (repeatable; "
        "recorded in run.json, so evaluate imports it again)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``tlshield`` command."""
    parser = argparse.ArgumentParser(
        prog="tlshield",
        description="Temporal-logic guided safe reinforcement learning with CBF shields.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="robustness of the paper's task on sample trajectories")
    demo.add_argument("--steps", type=int, default=200, help="trajectory length T (default 200)")
    demo.add_argument("--half-width", type=float, default=1.5, help="channel half-width w")
    demo.add_argument("--goal-radius", type=float, default=0.5, help="goal radius")
    demo.set_defaults(handler=_demo)

    fsa = sub.add_parser("fsa", help="print the automaton of a formula (states, guards, safe sets)")
    fsa.add_argument(
        "formula", nargs="?", default=TASK, help="scTLTL formula (default: the paper's task)"
    )
    fsa.add_argument("--dot", metavar="PATH", help="write Graphviz DOT text to PATH")
    fsa.add_argument("--png", metavar="PATH", help="render a PNG to PATH (needs graphviz)")
    fsa.set_defaults(handler=_fsa)

    from tlshield.envs.channel import CONFIGS

    train = sub.add_parser("train", help="train PPO on one configuration of the case study")
    train.add_argument(
        "--config",
        choices=sorted(CONFIGS),
        default=None,
        help="configuration (default: the one --settings names, else rl_cbf_clf)",
    )
    train.add_argument(
        "--env",
        default=ENV_ID,
        help="a registered Gymnasium id, or module:Env-v0 (module is imported first, as in "
        "gymnasium.make), whose factory takes config= and evaluation= and wraps the task "
        "(tlshield.wrappers.FsaAugmented, tlshield.wrappers.Shielded); default: the paper's "
        f"case study. Bundled: {ENV_ID}, {POINT_MASS_ID}, {FLATWORLD_ID} (--set formula=...)",
    )
    _add_import(train)
    train.add_argument(
        "--updates",
        type=_positive,
        default=DEFAULT_UPDATES,
        help=f"PPO updates (1024 steps each by default; default {DEFAULT_UPDATES})",
    )
    train.add_argument("--seed", type=int, default=0)
    train.add_argument("--out", required=True, help="run folder to write")
    train.add_argument("--evaluate", action="store_true", help="evaluate after training")
    train.add_argument("--trials", type=_positive, default=DEFAULT_TRIALS, help="evaluation trials")
    train.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_schedule(train)
    _add_preset(train)
    _add_settings(train)
    train.set_defaults(handler=_train)

    evaluate = sub.add_parser("evaluate", help="evaluate saved runs (CBF on, paper's rules)")
    evaluate.add_argument("runs", nargs="+", help="run folders")
    evaluate.add_argument("--trials", type=_positive, default=DEFAULT_TRIALS)
    evaluate.add_argument(
        "--policy",
        choices=("kept", "last"),
        default="kept",
        help="the kept policy (model.zip, default) or the last one (last_model.zip)",
    )
    evaluate.add_argument(
        "--trust-pickles",
        action="store_true",
        help="also load older run folders whose statistics are a pickle (vecnormalize.pkl); "
        "loading a pickle runs its code: only for folders you made yourself",
    )
    _add_import(evaluate)
    evaluate.set_defaults(handler=_evaluate)

    repro = sub.add_parser(
        "reproduce", help="all configurations x seeds, then figures and a results table"
    )
    repro.add_argument("--out", default="results", help="results folder (default: results)")
    repro.add_argument("--configs", nargs="+", choices=sorted(CONFIGS), default=list(CONFIGS))
    repro.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    repro.add_argument(
        "--updates", type=_positive, default=DEFAULT_UPDATES, help="PPO updates per run"
    )
    repro.add_argument(
        "--trials", type=_positive, default=DEFAULT_TRIALS, help="evaluation trials per run"
    )
    _add_ray(repro)
    repro.add_argument("--quiet", action="store_true")
    _add_schedule(repro)
    _add_preset(repro)
    _add_settings(repro)
    repro.set_defaults(handler=_reproduce)

    abl = sub.add_parser(
        "ablation", help="rl_cbf_clf from the paper's settings to the defaults, one change a row"
    )
    abl.add_argument("--out", default="results_ablation", help="folder (default: results_ablation)")
    abl.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    abl.add_argument("--updates", type=_positive, default=STUDY_UPDATES, help="PPO updates per run")
    abl.add_argument(
        "--trials", type=_positive, default=DEFAULT_TRIALS, help="evaluation trials per run"
    )
    _add_ray(abl)
    abl.add_argument("--quiet", action="store_true")
    abl.set_defaults(handler=_ablation)

    tune = sub.add_parser(
        "tune", help="search the task, shield and PPO settings (Ray Tune, Optuna, ASHA)"
    )
    tune.add_argument("--config", choices=sorted(CONFIGS), default=FULL)
    tune.add_argument("--samples", type=_positive, default=32, help="samples (default 32)")
    tune.add_argument(
        "--updates", type=_positive, default=STUDY_UPDATES, help="PPO updates per sample"
    )
    tune.add_argument("--out", default="results_tune", help="folder (default: results_tune)")
    tune.add_argument(
        "--search",
        nargs="+",
        metavar="NAME",
        help="settings to search (default: every one that applies to the configuration)",
    )
    tune.add_argument("--seed", type=int, default=3, help="training seed of every sample")
    tune.add_argument(
        "--trials", type=_positive, default=50, help="tuning evaluation trials per sample"
    )
    _add_ray(tune)
    tune.add_argument("--quiet", action="store_true")
    tune.set_defaults(handler=_tune)

    bench = sub.add_parser(
        "benchmark",
        help="published benchmarks: FlatWorld against DeepLTL's table; Safety-Gymnasium "
        "against OmniSafe's",
    )
    bench.add_argument("suite", choices=["flatworld", "safety-gym"], help="which benchmark")
    bench.add_argument(
        "--formulas", nargs="+", metavar="FORMULA", help="flatworld: default DeepLTL's five"
    )
    bench.add_argument(
        "--envs",
        nargs="+",
        metavar="ENV",
        help="safety-gym: default SafetyPointGoal1-v0 SafetyPointGoal2-v0 SafetyCarGoal1-v0",
    )
    bench.add_argument(
        "--configs",
        nargs="+",
        metavar="CONFIG",
        help="trained configurations (default: flatworld rl_cbf_clf rl; safety-gym rl rl+native "
        "rl_cbf rl_cbf_clf); safety-gym also takes rl_clf and the levers rl_cbf+penalty "
        "rl_cbf+executed rl_cbf_clf+small_std rl_cbf_clf+small_std+tanh",
    )
    bench.add_argument(
        "--seeds", nargs="+", type=int, help="default: flatworld 1 2 3; safety-gym 0 1 2"
    )
    bench.add_argument(
        "--sensing",
        nargs="+",
        metavar="SENSING",
        help="safety-gym: what the shield reads, each a row of its own (default: state, "
        "MuJoCo's true state; lidar: the policy's observation alone)",
    )
    bench.add_argument(
        "--episodes",
        type=_positive,
        help="evaluation episodes (default: flatworld 500; safety-gym 10)",
    )
    bench.add_argument(
        "--steps",
        type=_positive,
        help="PPO steps per agent (default: flatworld 600000; safety-gym 1000000 on "
        "PointGoal1 and CarGoal1, 300000 on PointGoal2)",
    )
    bench.add_argument("--out", help="(default: results_flatworld, results_safety_gym)")
    _add_ray(bench)
    bench.add_argument("--quiet", action="store_true")
    bench.set_defaults(handler=_benchmark)

    plot = sub.add_parser("plot", help="figures and the results table from a results folder")
    plot.add_argument("results", help="results folder (as written by reproduce)")
    plot.add_argument("--out", help="figures folder (default: RESULTS/figures)")
    plot.set_defaults(handler=_plot)
    return parser


def _benchmark(args: argparse.Namespace) -> int:
    if args.suite == "safety-gym":
        return _benchmark_safety_gym(args)
    if args.envs:
        raise ValueError("--envs: the flatworld benchmark has one env; use --formulas")
    if args.sensing:
        raise ValueError("--sensing: the flatworld benchmark's shield reads its own state")
    from tlshield.lab import benchmark

    out = benchmark.flatworld(
        args.out or "results_flatworld",
        formulas=args.formulas,
        configs=args.configs or list(benchmark.DEFAULT_CONFIGS),
        seeds=args.seeds or list(benchmark.DEFAULT_SEEDS),
        episodes=args.episodes or benchmark.DEFAULT_EPISODES,
        steps=args.steps or benchmark.DEFAULT_STEPS,
        **_ray_options(args),
    )
    print((out / "flatworld.md").read_text())
    print(f"wrote {out / 'flatworld.csv'}, {out / 'flatworld.md'}, {out / 'flatworld_paths.png'}")
    return 0


def _benchmark_safety_gym(args: argparse.Namespace) -> int:
    from tlshield.lab import benchmark_safety_gym as sg

    if args.formulas:
        raise ValueError("--formulas: the safety-gym benchmark's task is Safety-Gymnasium's")
    out = sg.safety_gym(
        args.out or "results_safety_gym",
        envs=args.envs or tuple(sg.DEFAULT_STEPS),
        configs=args.configs or sg.DEFAULT_CONFIGS,
        seeds=args.seeds or sg.DEFAULT_SEEDS,
        sensing=args.sensing or sg.DEFAULT_SENSING,
        steps=args.steps,
        episodes=args.episodes or sg.DEFAULT_EPISODES,
        **_ray_options(args),
    )
    print((out / "safety_gym.md").read_text())
    print(f"wrote {out / 'safety_gym.csv'}, {out / 'safety_gym.md'}, {out / 'safety_gym.png'}")
    return 0


def _one_line(err: BaseException) -> str:
    """An error as one line: an OSError as "what: path", anything else by its message."""
    if isinstance(err, OSError) and err.strerror and err.filename is not None:
        text = f"{err.strerror}: {err.filename}"
        if err.filename2 is not None:
            text += f" -> {err.filename2}"
    else:
        text = str(err) or type(err).__name__
    return " ".join(text.split())


def working_folder_first() -> None:
    """Puts the working folder first on ``sys.path``, as ``python -m tlshield`` does: the
    ``tlshield`` console script starts with its own folder there instead, and ``--env
    module:Env-v0`` and ``--import`` must find a module where the user runs the command."""
    here = os.getcwd()
    if here not in sys.path and "" not in sys.path:
        sys.path.insert(0, here)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tlshield`` and ``python -m tlshield``."""
    working_folder_first()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args))
    except ModuleNotFoundError as err:
        if (err.name or "").split(".")[0] not in TRAINING_MODULES:
            raise
        print(
            f"tlshield {args.command}: needs the training extra (no module named "
            f"{err.name!r}); install it with: pip install 'tlshield[train]'",
            file=sys.stderr,
        )
        return 2
    except MissingStack as err:
        print(f"tlshield {args.command}: {err}", file=sys.stderr)
        return 2
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, gym_error.Error) as err:
        # Bad paths and files (missing, the wrong kind, unwritable, corrupt, truncated) and
        # environments Gymnasium cannot make: one line, exit 2, as argparse reports a bad
        # argument.
        print(f"tlshield {args.command}: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except RuntimeError as err:
        print(f"tlshield {args.command}: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(
            f"tlshield {args.command}: interrupted; finished runs and metrics so far are kept",
            file=sys.stderr,
        )
        return 130
