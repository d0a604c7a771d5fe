"""tlshield's higher-order CBF against cbfpy (JAX) on the same double-integrator CBF-QP.

The problem: a 2-D double integrator (state ``[x, y, vx, vy]``, input the acceleration) kept
out of a disc of radius 0.5 by a relative-degree-2 barrier ``h = |p - o| - r``; both filters
solve ``min |u - u_des|^2`` subject to the HOCBF condition ``psi_1' + alpha2 psi_1 >= 0`` with
``psi_1 = h' + alpha1 h`` (cbfpy: ``h_2``, ``alpha_2 = alpha1 h``, ``alpha = alpha2 h``; its
derivatives by JAX autodiff, ours in closed form). Before timing, both must agree on every one
of the random steps within 1e-5. Then: the median time per step from Python, cbfpy's
``safety_filter`` jit-compiled and warm (one call per step, as a control loop makes it) vs
``Shield.filter``.

Run: ``.venv/bin/python benches/compare_cbfpy.py [--quick]`` (cbfpy comes with the ``bench``
extra). Exit 1 when the two disagree, 2 when the speed target is missed.
"""

from __future__ import annotations

import os

# cbfpy's recommended CPU settings, before JAX is imported: float64, single-threaded.
os.environ.setdefault("JAX_ENABLE_X64", "1")
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import statistics
import time
import warnings
from collections.abc import Callable

import numpy as np

import tlshield

OBSTACLE, RADIUS, MARGIN = np.array([2.0, 0.1]), 0.5, 1e-6
ALPHA1, ALPHA2 = 1.5, 2.0
AGREEMENT = 1e-5
TARGET = 10.0


def tlshield_filter() -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    far = tlshield.Ball(pos=[0, 1], radius=0.1, center=[100.0, 100.0])
    shield = tlshield.Shield(
        tlshield.Spec("F far", {"far": far}),
        tlshield.DoubleIntegrator(pos=[0, 1], vel=[2, 3]),
        alpha=ALPHA1,
        alpha2=ALPHA2,
        c3=1.0,
        k=1e4,
        cbf_bounds=(-1e3, 1e3),
        clf_bounds=(-1.0, 1.0),
        use_clf=False,
        margin=MARGIN,
        barriers={"!o": tlshield.Avoid(tlshield.Ball(pos=[0, 1], radius=RADIUS, center=OBSTACLE))},
    )
    return lambda s, u: shield.filter(s, 0, u).action


def cbfpy_filter() -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import jax
        import jax.numpy as jnp
        from cbfpy import CBF, CBFConfig

    class Config(CBFConfig):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__(n=4, m=2, relax_qp=False, solver_tol=1e-10)

        def f(self, z: object) -> object:
            return jnp.concatenate([z[2:], jnp.zeros(2)])  # type: ignore[index]

        def g(self, z: object) -> object:
            return jnp.vstack([jnp.zeros((2, 2)), jnp.eye(2)])

        def h_2(self, z: object) -> object:
            d = jnp.linalg.norm(z[:2] - jnp.asarray(OBSTACLE))  # type: ignore[index]
            return jnp.array([d - RADIUS - MARGIN])

        def alpha_2(self, h: object) -> object:
            return ALPHA1 * h  # type: ignore[operator]

        def alpha(self, h: object) -> object:
            return ALPHA2 * h  # type: ignore[operator]

    cbf = CBF.from_config(Config())
    step = jax.jit(cbf.safety_filter)
    return lambda s, u: np.asarray(step(jnp.asarray(s), jnp.asarray(u)))


def states(count: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random (s, u_des): positions 0.05-3 m from the obstacle's edge, speeds up to 2 m/s,
    desired accelerations up to 3 m/s^2."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        angle, dist = rng.uniform(-np.pi, np.pi), rng.uniform(RADIUS + 0.05, RADIUS + 3.0)
        p = OBSTACLE + dist * np.array([np.cos(angle), np.sin(angle)])
        out.append((np.concatenate([p, rng.uniform(-2, 2, 2)]), rng.uniform(-3, 3, 2)))
    return out


def median_us(run: Callable[[np.ndarray, np.ndarray], np.ndarray], items: list, reps: int) -> float:
    times = []
    for _ in range(reps):
        start = time.perf_counter()
        for s, u in items:
            run(s, u)
        times.append((time.perf_counter() - start) / len(items) * 1e6)
    return statistics.median(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="fewer steps (smoke run)")
    args = parser.parse_args()
    count, reps = (100, 3) if args.quick else (1000, 7)
    ours, theirs = tlshield_filter(), cbfpy_filter()
    items = states(count, args.seed)
    worst, corrected, worst_corrected = 0.0, 0, 0.0
    for s, u in items:
        a, b = ours(s, u), theirs(s, u)
        diff = float(np.max(np.abs(a - b)))
        worst = max(worst, diff)
        if np.max(np.abs(a - u)) > 1e-6:
            corrected += 1
            worst_corrected = max(worst_corrected, diff)
    from importlib.metadata import version

    import jax

    versions = f"tlshield {tlshield.__version__}, cbfpy {version('cbfpy')}, qpax {version('qpax')}"
    print(f"versions: {versions}, jax {jax.__version__} (float64, CPU, single-threaded)")
    print(
        f"agreement on {count} random steps (seed {args.seed}): max |action difference| "
        f"{worst:.2e} (limit {AGREEMENT:g}); on the {corrected} steps the barrier corrected: "
        f"{worst_corrected:.2e}"
    )
    if worst > AGREEMENT:
        return 1
    t_ours = median_us(ours, items, reps)
    t_theirs = median_us(theirs, items, reps)
    ratio = t_theirs / t_ours
    verdict = "ok" if ratio >= TARGET else "MISSED"
    print("\n| implementation | us per step |\n|---|---:|")
    print(f"| tlshield `Shield.filter` (HOCBF, closed form) | {t_ours:.2f} |")
    print(f"| cbfpy `safety_filter` (jit, warm; qpax) | {t_theirs:.2f} |")
    print(f"\ntlshield speedup: {ratio:.1f}x (target >= {TARGET:g}x, {verdict})")
    return 0 if ratio >= TARGET else 2


if __name__ == "__main__":
    raise SystemExit(main())
