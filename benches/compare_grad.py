"""Forward + backward through the shield's QP: ``tlshield.torch.ShieldLayer`` against the dense
differentiable QP layers a PyTorch or JAX user would reach for, qpth, cvxpylayers and qpax, on
the same paper-task problems, in one run so that machine noise cancels in the ratios.

One call = the safe actions of a batch of B states (forward) and ``dL/da_rl`` for an upstream
gradient (backward), B in 1, 64, 1,024, 16,384 and 65,536 (cvxpylayers up to 1,024 and qpth up
to 16,384 rows: beyond, one call takes minutes). The problems are the random case-study steps of
``compare_shield.py``. The baselines get the QP's rows from ``tests/shield_reference.py``
(numpy, built before the clock starts, so they are timed on the QP alone) with the right-hand
sides written in torch as functions of ``a_rl``, and solve (only steps whose QP is feasible as
posed are drawn: the baselines have no relaxation):

* qpth (``QPFunction``, batched primal-dual interior point in torch, its own KKT backward, at its
  default settings). qpth needs a positive definite ``Q`` and a well-scaled problem: the slack
  is solved for as ``d' = K d`` (cost 1 per unit) with a curvature of 1e-10. Even so its
  interior point stops short on some of these problems (the agreement line reports on how
  many): it is timed as it is, and its answers are reported, not required to agree;
* cvxpylayers (diffcp with Clarabel, the DPP problem of ``CvxpyShield``, batched);
* qpax (``solve_qp_primal``: a primal-dual interior point in JAX with an implicit-function
  backward; ``jax.jit`` of ``jax.vmap`` over the rows, float64, on whatever device JAX has:
  the CPU where JAX is installed without CUDA), on qpth's scaled problem.

tlshield is timed on the whole step (FSA state given; predicates, safe set, goal, rows, QP)
through the layer, with torch tensors in and out. Before timing, every implementation must give
the same actions and ``a_rl`` gradients as tlshield on the B = 64 batch (within the tolerance
printed). Times are per call: p50 and p99 over repeated calls; ratios are of p50 and of p99.

Run: ``.venv/bin/python benches/compare_grad.py [--quick]``. Exit 1 when a check fails, 2 when
the speed target (>= 100x against both at every batch size) is missed.
"""

from __future__ import annotations

import argparse
import gc
import os
import platform
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from compare_robustness import package_version
from compare_shield import make_shield, make_steps

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from tests.shield_reference import MAX_BARRIERS, Params, Structure, Task, build_rows

TARGET = 100.0
BATCHES = (1, 64, 1024, 16384, 65536)
#: The largest batch each slow baseline is timed on (one call of the next size takes minutes).
LARGEST = {"qpth": 16384, "cvxpylayers": 1024}
#: qpth's curvature on the scaled slack d' = K d (it needs Q positive definite).
QPTH_SLACK_CURVATURE = 1e-10


def qp_data(rows_list: list[Any], a_rl: np.ndarray, params: Params) -> dict[str, np.ndarray]:
    """The batch's QPs over x = [a_cbf, a_clf, d]: G (B, R, 5) and h as ``h0 + H a_rl`` (H is
    (B, R, 2)), padded as CvxpyShield pads them; also the cvxpylayers parameters."""
    b, r = len(rows_list), MAX_BARRIERS + 2 + 8
    g = np.zeros((b, r, 5))
    h0 = np.zeros((b, r))
    hh = np.zeros((b, r, 2))
    lg = np.zeros((b, MAX_BARRIERS, 2))
    rhs0 = np.ones((b, MAX_BARRIERS))
    clf_lg = np.zeros((b, 2))
    clf0 = np.zeros(b)
    clf_h = np.zeros((b, 2))
    box = np.zeros((b, 2, 2))
    lo, hi = params.cbf
    clo, chi = params.clf
    for i, rows in enumerate(rows_list):
        nb = rows.lg.shape[0]
        # rhs = (rhs - lg . a_rl) + lg . a_rl: the part in a_rl written out.
        base = rows.rhs - rows.lg @ a_rl[i]
        g[i, :nb, 0:2] = -rows.lg
        g[i, :nb, 2:4] = -rows.lg
        h0[i, :MAX_BARRIERS] = 1.0
        h0[i, :nb] = base
        hh[i, :nb] = rows.lg
        lg[i, :nb], rhs0[i, :nb] = rows.lg, base
        # CLF row: with delta_0 = 0 its rhs is c0 - Lg V . a_rl; with delta_0 > 0 it is the
        # box's bound, constant.
        k = MAX_BARRIERS
        g[i, k, 2:4], g[i, k, 4] = rows.clf_lg, -1.0
        if rows.delta_0 > 0.0:
            h0[i, k] = rows.clf_rhs
        else:
            h0[i, k] = rows.clf_rhs + rows.clf_lg @ a_rl[i]
            hh[i, k] = -rows.clf_lg
        clf_lg[i], clf0[i], clf_h[i] = rows.clf_lg, h0[i, k], hh[i, k]
        g[i, k + 1, 4] = -1.0
        c_lo, c_hi = (clo, chi) if rows.has_goal else (0.0, 0.0)
        box[i] = [[c_lo, c_lo], [c_hi, c_hi]]
        for j in range(4):
            upper, lower = (hi, lo) if j < 2 else (c_hi, c_lo)
            g[i, k + 2 + 2 * j, j], h0[i, k + 2 + 2 * j] = 1.0, upper
            g[i, k + 3 + 2 * j, j], h0[i, k + 3 + 2 * j] = -1.0, -lower
    return {
        "G": g,
        "h0": h0,
        "H": hh,
        "lg": lg,
        "rhs0": rhs0,
        "clf_lg": clf_lg,
        "clf0": clf0,
        "clf_h": clf_h,
        "box": box,
    }


def ms(seconds: float) -> str:
    """Milliseconds as the tables print them: three decimals under 10 ms, one above."""
    return f"{seconds * 1e3:.3f}" if seconds < 0.01 else f"{seconds * 1e3:,.1f}"


def ratio(r: float) -> str:
    """A speedup as the tables print it: whole numbers from 10x, two decimals below."""
    return f"{r:,.0f}x" if r >= 10 else f"{r:.2f}x"


def percentiles(call: Callable[[], object], budget: float, min_reps: int) -> tuple[float, float]:
    """p50 and p99 seconds of ``call`` timed alone, repeated for about ``budget`` seconds."""
    call()  # warm-up
    times: list[float] = []
    gc.collect()
    start = time.perf_counter()
    while len(times) < min_reps or (time.perf_counter() - start < budget and len(times) < 2000):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    p50, p99 = np.percentile(times, [50, 99])
    return float(p50), float(p99)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="small batches, few repetitions")
    args = parser.parse_args(argv)
    batches = (1, 8) if args.quick else BATCHES
    budget = 0.5 if args.quick else 10.0

    import jax
    import jax.numpy as jnp
    import qpax
    import torch
    from cvxpylayers.torch import CvxpyLayer
    from qpth.qp import QPFunction

    jax.config.update("jax_enable_x64", True)

    import tlshield
    from tests.shield_reference import CvxpyShield
    from tlshield.torch import ShieldLayer

    torch.set_num_threads(2)
    warnings.filterwarnings("ignore", category=UserWarning)
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    params, task = Params(), Task()
    shield = make_shield()
    aut = shield.automaton
    structure = Structure(aut)
    layer = ShieldLayer(shield)
    cvx = CvxpyShield(params)
    cvx_layer = CvxpyLayer(
        cvx.problem,
        parameters=[cvx.lg, cvx.rhs, cvx.clf_lg, cvx.clf_rhs, cvx.clf_lo, cvx.clf_hi],
        variables=[cvx.a_cbf, cvx.a_clf, cvx.d],
    )
    cvx_args = {"solve_method": "Clarabel"}
    qp_fn = QPFunction(verbose=-1, check_Q_spd=False)
    q_diag = torch.tensor([2.0, 2.0, 2.0, 2.0, QPTH_SLACK_CURVATURE], dtype=torch.float64)
    p_vec = torch.tensor([0.0, 0.0, 0.0, 0.0, 1.0], dtype=torch.float64)
    empty = torch.empty(0, dtype=torch.float64)

    rng = np.random.default_rng(args.seed)
    largest = max(batches)
    # Steps whose QP is feasible as posed (the baselines have no relaxation) and that have a CLF
    # goal (without one the CLF box is {0}: no interior for the interior-point baselines).
    steps = make_steps(rng, 3 * max(largest, 64) + 64)
    states = np.array([s for s, _ in steps])
    actions = np.array([a for _, a in steps])
    qs = np.array([aut.step(s, aut.initial) for s in states])
    solved = shield.filter_batch(states, qs, actions).status == tlshield.Status.SOLVED
    has_goal = np.array([aut.goal(s, int(q)) is not None for s, q in zip(states, qs, strict=True)])
    keep = solved & has_goal
    states, actions, qs = states[keep], actions[keep], qs[keep]
    assert len(states) >= largest, len(states)
    upstream = rng.normal(size=actions.shape)

    def problems(n: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
        rows = [
            build_rows(task, structure, params, states[i], int(qs[i]), actions[i]) for i in range(n)
        ]
        return qp_data(rows, actions[:n], params), actions[:n]

    def run_tlshield(n: int) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
        s_t, q = torch.from_numpy(states[:n]), qs[:n]
        v = torch.from_numpy(upstream[:n])

        def call() -> tuple[np.ndarray, np.ndarray]:
            a = torch.tensor(actions[:n], requires_grad=True)
            out = layer(s_t, q, a)
            (out * v).sum().backward()
            assert a.grad is not None
            return out.detach().numpy(), a.grad.numpy()

        return call

    def run_tlshield_cuda(n: int) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
        """The layer with every tensor on the GPU (the result and gradient come back there)."""
        dev = torch.device("cuda")
        s_t, q = torch.from_numpy(states[:n]).to(dev), torch.from_numpy(qs[:n]).to(dev)
        v, a0 = torch.from_numpy(upstream[:n]).to(dev), torch.from_numpy(actions[:n]).to(dev)

        def call() -> tuple[np.ndarray, np.ndarray]:
            a = a0.clone().requires_grad_(True)
            out = layer(s_t, q, a)
            (out * v).sum().backward()
            assert a.grad is not None
            torch.cuda.synchronize()
            return out.detach().cpu().numpy(), a.grad.cpu().numpy()

        return call

    def run_qpth(n: int) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
        data, a_np = problems(n)
        qmat = torch.diag(q_diag).expand(n, 5, 5)
        p = p_vec.expand(n, 5)
        g = torch.from_numpy(data["G"] * np.array([1.0, 1.0, 1.0, 1.0, 1.0 / params.k]))
        h0, hh = torch.from_numpy(data["h0"]), torch.from_numpy(data["H"])
        v = torch.from_numpy(upstream[:n])

        def call() -> tuple[np.ndarray, np.ndarray]:
            a = torch.tensor(a_np, requires_grad=True)
            h = h0 + (hh @ a.unsqueeze(-1)).squeeze(-1)
            x = qp_fn(qmat, p, g, h, empty, empty)
            out = a + x[:, 0:2] + x[:, 2:4]
            (out * v).sum().backward()
            assert a.grad is not None
            return out.detach().numpy(), a.grad.numpy()

        return call

    def run_cvxpylayers(n: int) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
        data, a_np = problems(n)
        lg, rhs0 = torch.from_numpy(data["lg"]), torch.from_numpy(data["rhs0"])
        clf_lg, clf0 = torch.from_numpy(data["clf_lg"]), torch.from_numpy(data["clf0"])
        clf_h = torch.from_numpy(data["clf_h"])
        lo, hi = torch.from_numpy(data["box"][:, 0]), torch.from_numpy(data["box"][:, 1])
        v = torch.from_numpy(upstream[:n])

        def call() -> tuple[np.ndarray, np.ndarray]:
            a = torch.tensor(a_np, requires_grad=True)
            rhs = rhs0 + (lg @ a.unsqueeze(-1)).squeeze(-1)
            clf_rhs = clf0 + (clf_h * a).sum(-1)
            a_cbf, a_clf, _ = cvx_layer(lg, rhs, clf_lg, clf_rhs, lo, hi, solver_args=cvx_args)
            out = a + a_cbf + a_clf
            (out * v).sum().backward()
            assert a.grad is not None
            return out.detach().numpy(), a.grad.numpy()

        return call

    def run_core(n: int) -> Callable[[], np.ndarray]:
        """The core alone, from numpy: actions and Jacobians, then the product."""
        s, q, a, v = states[:n], qs[:n], actions[:n], upstream[:n]

        def call() -> np.ndarray:
            _, jac, _, _ = shield.jacobian_batch(s, q, a, state_grad=False)
            return np.einsum("bk,bkj->bj", v, jac)

        return call

    def run_torch_floor(n: int) -> Callable[[], None]:
        """torch's own cost of a call: a trivial differentiable map, forward and backward."""
        v = torch.from_numpy(upstream[:n])

        def call() -> None:
            a = torch.tensor(actions[:n], requires_grad=True)
            ((a * 2.0) * v).sum().backward()

        return call

    def run_qpax(n: int) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
        """qpax on qpth's scaled problem: one jit-compiled vmap of forward and gradient."""
        data, a_np = problems(n)
        g = jnp.asarray(data["G"] * np.array([1.0, 1.0, 1.0, 1.0, 1.0 / params.k]))
        h0, hh = jnp.asarray(data["h0"]), jnp.asarray(data["H"])
        qmat, p = jnp.diag(jnp.asarray(q_diag.numpy())), jnp.asarray(p_vec.numpy())
        no_a, no_b = jnp.zeros((0, 5)), jnp.zeros(0)
        v = jnp.asarray(upstream[:n])

        def row(a: Any, g: Any, h0: Any, hh: Any, v: Any) -> tuple[Any, Any]:
            x = qpax.solve_qp_primal(qmat, p, no_a, no_b, g, h0 + hh @ a)
            out = a + x[0:2] + x[2:4]
            return out @ v, out

        grad_row = jax.grad(row, has_aux=True)
        step = jax.jit(jax.vmap(grad_row))
        a_in = jnp.asarray(a_np)

        def call() -> tuple[np.ndarray, np.ndarray]:
            grad, out = step(a_in, g, h0, hh, v)
            return np.asarray(out), np.asarray(grad)

        return call

    runners = {"qpth": run_qpth, "cvxpylayers": run_cvxpylayers, "qpax": run_qpax}

    # --- agreement on one batch ----------------------------------------------------------------
    check = min(64, largest) if not args.quick else 8
    want_out, want_grad = run_tlshield(check)()
    flags = shield.vjp_batch(states[:check], qs[:check], actions[:check], upstream[:check])[2]
    ok = flags == 0
    failed = False
    print(f"agreement on {check} paper-task steps ({int(ok.sum())} without gradient flags):")
    accuracy = {}
    for name, make in runners.items():
        out, grad = make(check)()
        act_err = np.abs(out - want_out).max(axis=1)
        grad_err = np.abs(grad - want_grad).max(axis=1)
        close = (act_err <= 1e-3) & (grad_err <= 1e-2)
        accuracy[name] = f"{int(close[ok].sum())} / {int(ok.sum())}"
        print(
            f"  {name}: actions within 1e-3 and a_rl gradients within 1e-2 on "
            f"{accuracy[name]} steps; median errors {np.median(act_err):.1e} (action), "
            f"{np.median(grad_err[ok]):.1e} (gradient), worst {act_err.max():.1e}, "
            f"{grad_err[ok].max():.1e}"
        )
        # The formulation must be the same problem: most steps agree (qpth may stop short).
        if np.median(act_err) > 1e-4:
            print(f"  FAILED: {name} solves a different problem")
            failed = True
    if failed:
        return 1

    # --- timing -------------------------------------------------------------------------------
    rows_out = []
    missed = False
    for n in batches:
        base = percentiles(run_tlshield(n), budget, 20)
        line = {"B": n, "tlshield": base}
        if torch.cuda.is_available():
            line["cuda"] = percentiles(run_tlshield_cuda(n), budget / 2, 20)
        line["core"] = percentiles(run_core(n), budget / 2, 20)
        line["floor"] = percentiles(run_torch_floor(n), budget / 2, 20)
        for name, make in runners.items():
            if n > LARGEST.get(name, n):
                continue
            reps = 3 if n >= 16384 else 5 if n >= 1024 else 10
            line[name] = percentiles(make(n), budget, reps)
            r50, r99 = line[name][0] / base[0], line[name][1] / base[1]
            if name in LARGEST:  # the speed target is against the torch layers
                missed |= min(r50, r99) < TARGET
        rows_out.append(line)

    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    print()
    print(
        f"commit {commit or '?'}, {platform.machine()} {platform.system()}, "
        f"torch {package_version('torch')}, qpth {package_version('qpth')}, "
        f"cvxpylayers {package_version('cvxpylayers')}, diffcp {package_version('diffcp')}, "
        f"qpax {package_version('qpax')} (jax {package_version('jax')} on "
        f"{jax.default_backend()}), {os.cpu_count()} cores, seed {args.seed}"
    )
    print()
    names = list(runners)
    print(
        "| batch | tlshield p50 / p99 (ms) | "
        + " | ".join(f"{name} p50 / p99 (ms)" for name in names)
        + " | "
        + " | ".join(f"tlshield speedup vs {name} (p50 / p99)" for name in names)
        + " |"
    )
    print("|---:|" + "---:|" * (1 + 2 * len(names)))
    for line in rows_out:
        t = line["tlshield"]
        times = [f"{ms(line[k][0])} / {ms(line[k][1])}" if k in line else "-" for k in names]
        ratios = [
            f"{ratio(line[k][0] / t[0])} / {ratio(line[k][1] / t[1])}" if k in line else "-"
            for k in names
        ]
        print(
            f"| {line['B']:,} | {t[0] * 1e3:.3f} / {t[1] * 1e3:.3f} | "
            + " | ".join(times + ratios)
            + " |"
        )
    print()
    print(
        "Where tlshield's time goes: the core alone (`jacobian_batch` from numpy and the "
        "product) and torch's own cost of any differentiable call (a trivial map, forward and "
        "backward), p50 / p99 in ms:"
    )
    print()
    print("| batch | core alone | torch floor | the layer |")
    print("|---:|---:|---:|---:|")
    for line in rows_out:
        c, f, t = line["core"], line["floor"], line["tlshield"]
        print(
            f"| {line['B']:,} | {c[0] * 1e3:.3f} / {c[1] * 1e3:.3f} "
            f"| {f[0] * 1e3:.3f} / {f[1] * 1e3:.3f} | {t[0] * 1e3:.3f} / {t[1] * 1e3:.3f} |"
        )
    print()
    if torch.cuda.is_available():
        print("The layer with CUDA tensors against CPU tensors, p50 / p99 in ms (target: adds")
        print("<= 0.15 ms at 1,024 rows):\n")
        print("| batch | CPU tensors | CUDA tensors | added (p50) |")
        print("|---:|---:|---:|---:|")
        for line in rows_out:
            t, c = line["tlshield"], line["cuda"]
            print(
                f"| {line['B']:,} | {ms(t[0])} / {ms(t[1])} | {ms(c[0])} / {ms(c[1])} "
                f"| {ms(c[0] - t[0])} |"
            )
    else:
        print("No CUDA device: the layer with CUDA tensors is not timed here.")
    print()
    print(
        "steps each baseline solved as tlshield did (agreement check): "
        + ", ".join(f"{k} {v}" for k, v in accuracy.items())
    )
    print(
        f"tlshield speedup target >= {TARGET:.0f}x against qpth and cvxpylayers at every batch "
        "size each is timed on: "
        f"{'NOT MET' if missed else 'met'}"
    )
    return 2 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
