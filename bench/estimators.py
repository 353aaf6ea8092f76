"""idkit's estimators against their peers, measured in one run on this machine.

Run: ``python bench/estimators.py [--repeats 7] [--quick]``. Prints Markdown tables:

1. PSO at three sizes — one run, one 10-run estimate, a batch of 10,000 runs — for idkit (the fast
   and the eager engine), evosax's PSO (JAX ``jit`` + ``vmap``, float64) and pyswarms, all on the same f13
   problem (``torque_noise``, seed 0) with the same budget (20 particles, 300 iterations), with each
   peer's compile time beside its run time and the ratios; repeated calls fit the same ``Problem``
   (idkit reuses its objective, as evosax's compiled call reuses the arrays built before it), and
   one more row fits a new ``Problem`` object per call (idkit builds its objective in the call);
   GPU rows when CUDA is present;
2. the 10-run estimate in new processes, with and without a C compiler on ``PATH`` and with a fresh
   cache (``bench/no_compiler.py``): the first fit, the one-time build recorded apart, the later fits;
3. the whole Tables II–V workload, RLS closed form vs cvxpy, and the f1 quality hit rate.

Everything runs on one thread (torch, and XLA via ``XLA_FLAGS``, set before JAX is imported).
Times are the median of ``repeats`` calls after one warm-up (min in brackets); the 10,000-run
batches are timed once. The machine may be shared: the load average is printed with the tables.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import replace

import no_compiler  # noqa: E402  (bench/ is the script's folder)
import numpy as np

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")
import torch  # noqa: E402

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.linear.least_squares import LeastSquares, TotalLeastSquares
from idkit.estimators.linear.robust_ls import RobustLeastSquares
from idkit.estimators.pso import ParticleSwarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot

SCENARIOS = ("state_noise", "torque_noise", "all_noise", "outliers")
COSTS = [getattr(paper, f"f{i}")() for i in range(1, 17)]


def timed(function: Callable[[], object], repeats: int) -> tuple[float, float]:
    """(median, min) wall time in seconds of ``repeats`` calls after one warm-up call."""
    function()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return statistics.median(times), min(times)


def progress(message: str, started: float) -> None:
    print(f"[{time.perf_counter() - started:6.1f} s] {message}", file=sys.stderr, flush=True)


def once(function: Callable[[], object]) -> tuple[float, float]:
    """Wall time of one call (for the big batch, after smaller calls warmed everything up)."""
    start = time.perf_counter()
    function()
    elapsed = time.perf_counter() - start
    return elapsed, elapsed


def ms(t: tuple[float, float]) -> str:
    return f"{t[0] * 1e3:.2f} ms ({t[1] * 1e3:.2f})"


# --- pyswarms on the same cost --------------------------------------------------------------


def numpy_cost(robot: CylindricalRobot, problem: Problem, name: str) -> Callable[[np.ndarray], np.ndarray]:
    """f1 or f13 of particles ``[K, 4]`` in numpy, vectorised over particles as pyswarms expects."""
    s = problem.tensors()
    y = robot.regressor(s.q, s.qd, s.qdd).numpy()  # [N, n, B]
    measured = s.tau.numpy()  # [N, n]
    floor = paper.f13().floor
    rms = np.sqrt((measured**2).mean(axis=0))
    denominator = np.where(
        np.abs(measured) < floor * rms, np.where(measured < 0, -1, 1) * floor * rms, measured
    )

    def cost(x: np.ndarray) -> np.ndarray:
        m2, m3, s3z, inertia = x.T
        alpha = np.stack([inertia + m3 * s3z**2, m2, m3, m3 * s3z], axis=-1)  # [K, B]
        error = measured[None] - np.einsum("snb,kb->ksn", y, alpha)  # [K, N, n]
        if name == "f1":
            return np.sqrt((error**2).sum(axis=(1, 2)))
        rel = np.abs(error / denominator)
        return rel.sum(axis=2).max(axis=1) * rel.sum(axis=1).max(axis=1)  # ‖·‖₁ (columns) · ‖·‖∞ (rows)

    return cost


def pyswarms_run(robot: CylindricalRobot, cost: Callable, seed: int) -> tuple[float, np.ndarray]:
    """One pyswarms GlobalBestPSO run with the paper's settings (see the table's notes)."""
    import pyswarms

    np.random.seed(seed)
    lo, hi = (b.numpy() for b in robot.bounds())
    optimizer = pyswarms.single.GlobalBestPSO(
        n_particles=20,
        dimensions=4,
        options={"c1": 1.3, "c2": 1.3, "w": 0.9},
        bounds=(lo, hi),
        bh_strategy="nearest",
        vh_strategy="zero",
    )
    # The paper's inertia: 0.9 → 0.4 over the first 100 iterations, then 0.4.
    optimizer.oh.strategies["paper"] = lambda start, opt, **kw: 0.9 - 0.5 * min(kw["iternow"], 100) / 100
    optimizer.oh.strategy = {"w": "paper"}
    best_cost, best_pos = optimizer.optimize(cost, iters=300, verbose=False)
    return best_cost, best_pos


def pyswarms_runs(robot: CylindricalRobot, cost: Callable, runs: int) -> float:
    """Wall time of ``runs`` pyswarms runs one after another (it has no batch of runs)."""
    start = time.perf_counter()
    for seed in range(runs):
        pyswarms_run(robot, cost, seed)
    return time.perf_counter() - start


# --- evosax (JAX) on the same cost -----------------------------------------------------------


def evosax_pso(robot: CylindricalRobot, problem: Problem, runs: int) -> tuple[Callable[[], object], float]:
    """evosax's PSO on f13, ``runs`` independent runs as one ``jit(vmap(run))``: (call, compile s).

    Same budget as idkit's paper preset: 20 particles, 1 initial evaluation + 299 moves, c1 = c2 =
    1.3, inertia 0.9 → 0.4 over the first 100 moves (passed into ``params`` each move), positions
    clipped to the box before each evaluation (evosax's PSO has no boundary rule). evosax draws
    ``r1``, ``r2`` once per particle, not per dimension. Compiled ahead of time (``lower`` +
    ``compile``), so the call time excludes compilation.
    """
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from evosax.algorithms import PSO

    s = problem.tensors()
    y = jnp.asarray(robot.regressor(s.q, s.qd, s.qdd).numpy())  # [N, n, B]
    measured = jnp.asarray(s.tau.numpy())  # [N, n]
    floor = paper.f13().floor
    rms = jnp.sqrt((measured**2).mean(axis=0))
    small = jnp.abs(measured) < floor * rms
    denominator = jnp.where(small, jnp.where(measured < 0, -1.0, 1.0) * floor * rms, measured)
    lo, hi = (jnp.asarray(b.numpy()) for b in robot.bounds())
    strategy = PSO(population_size=20, solution=jnp.zeros(4))
    params = strategy.default_params.replace(cognitive_coeff=1.3, social_coeff=1.3)

    def cost(x: jax.Array) -> jax.Array:  # [K, 4] -> [K]
        m2, m3, s3z, inertia = x.T
        alpha = jnp.stack([inertia + m3 * s3z**2, m2, m3, m3 * s3z], axis=-1)
        rel = jnp.abs((measured[None] - jnp.einsum("snb,kb->ksn", y, alpha)) / denominator)
        return rel.sum(axis=2).max(axis=1) * rel.sum(axis=1).max(axis=1)

    def one_run(key: jax.Array) -> tuple[jax.Array, jax.Array]:
        start, key = jax.random.split(key)
        x0 = lo + (hi - lo) * jax.random.uniform(start, (20, 4))
        state = strategy.init(start, x0, cost(x0), params)

        def move(i, carry):  # noqa: ANN001, ANN202
            state, key = carry
            key, ask, tell = jax.random.split(key, 3)
            p = params.replace(inertia_coeff=jnp.where(i < 100, 0.9 - 0.5 * i / 100, 0.4))
            x, state = strategy.ask(ask, state, p)
            x = jnp.clip(x, lo, hi)
            state, _ = strategy.tell(tell, x, cost(x), state, p)
            return state, key

        state, _ = jax.lax.fori_loop(0, 299, move, (state, key))
        return state.best_fitness, state.best_solution

    keys = jax.random.split(jax.random.key(0), runs)
    started = time.perf_counter()
    compiled = jax.jit(jax.vmap(one_run)).lower(keys).compile()
    compile_s = time.perf_counter() - started
    return (lambda: jax.block_until_ready(compiled(keys))), compile_s


# --- the benchmark --------------------------------------------------------------------------


def peers_table(robot: CylindricalRobot, problem: Problem, repeats: int, quick: bool) -> list[str]:
    """Markdown rows: the three sizes × (idkit fast, idkit eager, evosax, pyswarms)."""
    cost13 = numpy_cost(robot, problem, "f13")
    big = 2_000 if quick else 10_000
    peer_runs = 10 if quick else 20
    rows = []
    for label, runs in (("one PSO run", 1), ("one 10-run estimate", 10), (f"batch of {big:,} runs", big)):
        timing = timed if runs <= 10 else (lambda f, _: once(f))
        idkit = {}
        for engine in ("native", "eager"):
            pso = ParticleSwarm(preset="paper", runs=runs, threads=1, engine=engine, history=False)
            idkit[engine] = timing(lambda pso=pso: pso.fit(problem), repeats)
        evosax_call, evosax_compile = evosax_pso(robot, problem, runs)
        evosax = timing(evosax_call, repeats)
        if runs == 1:
            peer = timed(lambda: pyswarms_run(robot, cost13, 0), max(3, repeats // 2))
            peer_text = ms(peer)
        else:
            measured = min(runs, peer_runs)
            seconds = pyswarms_runs(robot, cost13, measured) * runs / measured
            peer = (seconds, seconds)
            peer_text = f"{seconds * 1e3:,.0f} ms" + (
                "" if measured == runs else f" (extrapolated from {measured} runs)"
            )
        best = idkit["native"][0]
        if runs == 1:
            evosax_one = evosax
        rows.append(
            f"| {label} | {ms(idkit['native'])} | {ms(idkit['eager'])} | {ms(evosax)} "
            f"| {evosax_compile:.2f} s | {peer_text} | {evosax[0] / best:.2f}× | {peer[0] / best:.1f}× |"
        )
    # A new Problem object per call: the estimator cannot reuse its objective (pso.Prepared) and
    # builds it in the call — what a fit of new data costs. (evosax's timed call closes over arrays
    # built once before it; new data would mean a new compile.)
    fresh = ParticleSwarm(preset="paper", runs=1, threads=1, engine="native", history=False)
    rebuilt = timed(lambda: fresh.fit(replace(problem)), 3 * repeats)
    rows.append(
        f"| one PSO run, a new `Problem` per call (objective built in the call) | {ms(rebuilt)} "
        f"| – | – | – | – | {evosax_one[0] / rebuilt[0]:.2f}× | – |"
    )
    two = ParticleSwarm(preset="paper", runs=big, threads=2, engine="native", history=False)
    took = once(lambda: two.fit(problem))
    rows.append(f"| batch of {big:,} runs, idkit fast on 2 threads | {ms(took)} | – | – | – | – | – | – |")
    return rows


def gpu_rows(robot: CylindricalRobot, data, repeats: int) -> list[str]:  # noqa: ANN001
    """idkit's eager engine on CUDA at the three sizes (only when a GPU is present)."""
    if not torch.cuda.is_available():
        return []
    problem = Problem(robot, data, paper.f13(), seed=0, device="cuda")
    rows = []
    for label, runs in (("one PSO run", 1), ("one 10-run estimate", 10), ("batch of 10,000 runs", 10_000)):
        pso = ParticleSwarm(preset="paper", runs=runs, history=False)
        took = timed(lambda pso=pso: pso.fit(problem), repeats)
        rows.append(f"| {label}, CUDA ({torch.cuda.get_device_name()}) | {ms(took)} |")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--quick", action="store_true", help="fewer repeats, runs and quality runs")
    args = parser.parse_args()
    repeats = 3 if args.quick else args.repeats
    torch.set_num_threads(1)
    load_before = os.getloadavg()
    started = time.perf_counter()
    robot = CylindricalRobot()
    data = {name: simulate(robot, name, seed=0) for name in SCENARIOS}
    rows: list[tuple[str, str, str, str]] = []  # (what, idkit, peer, ratio)

    # 1. The peers at three sizes.
    problem = Problem(robot, data["torque_noise"], paper.f13(), seed=0)
    peers = peers_table(robot, problem, repeats, args.quick)
    gpu = gpu_rows(robot, data["torque_noise"], repeats)
    progress("peers done", started)
    fresh = no_compiler.rows(repeats)
    progress("fresh processes done", started)

    # 2. Tables II–V workload.
    def workload() -> None:
        problems = [Problem(robot, data[name], seed=0) for name in SCENARIOS]
        ParticleSwarm(threads=1, history=False).fit_trials(problems, COSTS)  # 4 × 16 × 10 swarms
        for p in problems:
            for estimator in (LeastSquares, TotalLeastSquares, RobustLeastSquares):
                for relative in (False, True):
                    estimator(relative=relative).fit(p)

    whole = timed(workload, max(1, repeats // 3))
    rows.append(
        (
            "Tables II–V: 4 scenarios × (16 PSO costs × 10 runs, one fit_trials call + 6 LS-family rows) "
            "(target ≤ 2 s)",
            ms(whole),
            "paper: ≈ 4 × 16 × 3–8 s",
            "",
        )
    )

    progress("workload done", started)

    # 3. RLS closed form vs cvxpy.
    p = Problem(robot, data["torque_noise"])
    closed = timed(lambda: RobustLeastSquares().fit(p), repeats * 5)
    cvx = timed(lambda: RobustLeastSquares(solver="cvxpy").fit(p), repeats)
    rows.append(
        (
            "RLS estimate (whole fit), closed form vs cvxpy",
            ms(closed),
            "cvxpy " + ms(cvx),
            f"{cvx[0] / closed[0]:.0f}×",
        )
    )

    progress("RLS done", started)

    # 4. Quality: f1 on torque_noise, hit = within 0.1 % of the LS cost.
    p1 = Problem(robot, data["torque_noise"], paper.f1(), seed=0)
    ls = LeastSquares().fit(p1)
    target = float(p1.evaluate(torch.tensor(ls.vector(), dtype=torch.float64)))
    n_runs = 100 if args.quick else 400
    rates = {}
    for preset in ("paper", "default"):
        est = ParticleSwarm(preset=preset, runs=n_runs, history=False).fit(p1)
        rates[preset] = float((np.array(est.details["run_costs"]) <= 1.001 * target).mean())
    cost1 = numpy_cost(robot, p1, "f1")
    n_peer = 20 if args.quick else 50
    peer_costs = np.array([pyswarms_run(robot, cost1, seed)[0] for seed in range(n_peer)])
    rates["pyswarms"] = float((peer_costs <= 1.001 * target).mean())
    rows.append(
        (
            f"f1 quality: runs within 0.1 % of the LS cost, torque_noise "
            f"(target ≥ 95 %; {n_runs} / {n_peer} runs)",
            f"default {rates['default']:.0%}, paper preset {rates['paper']:.0%}",
            f"pyswarms {rates['pyswarms']:.0%}",
            "",
        )
    )

    import evosax
    import jax

    print(
        f"torch {torch.__version__}, jax {jax.__version__}, "
        f"evosax {getattr(evosax, '__version__', '0.3.x')}, "
        f"float64, CPU, 1 thread, {os.cpu_count()} cores; "
        f"load average before {load_before[0]:.1f}, after {os.getloadavg()[0]:.1f}"
    )
    print(
        "\n| PSO, f13, torque_noise, 20 particles × 300 iterations | idkit fast (numba) | idkit eager "
        "| evosax run | evosax compile | pyswarms | evosax / idkit | pyswarms / idkit |\n"
        "| --- | --- | --- | --- | --- | --- | --- | --- |"
    )
    print("\n".join(peers))
    print("\n" + no_compiler.HEADER)
    print("\n".join(fresh))
    if gpu:
        print("\n| GPU | idkit eager |\n| --- | --- |\n" + "\n".join(gpu))
    print("\n| measurement | idkit | peer | ratio |\n| --- | --- | --- | --- |")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print(
        "\nNotes: pyswarms 1.3 GlobalBestPSO with 20 particles, 300 iterations, c1 = c2 = 1.3, the paper's "
        "inertia schedule, walls 'nearest' + velocity 'zero' (its initial velocities are uniform [0, 1), "
        "idkit's paper preset starts at zero), cost in vectorised numpy. evosax: see evosax_pso's docstring. "
        "idkit: paper preset, float64, one thread, the whole estimator (10-run mean, exact cost, Estimate); "
        "ratios > 1 mean idkit is faster."
    )


if __name__ == "__main__":
    main()
