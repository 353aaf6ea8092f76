"""What a batched search's time is made of (the constants of ``idkit.optim.sizes``).

A search's time is about ``steps × (a + b × width)``: ``width`` evaluations per step (``pso``: runs ×
particles per iteration; ``adam``: starts per step), ``b`` the time of one evaluation and ``a`` the
fixed time of a step (the swarm update and kernel call; Adam's autograd pass). The cap on a search's
size counts ``a / b`` evaluations per step (``sizes.PSO_STEP_EVALUATIONS``,
``sizes.ADAM_STEP_EVALUATIONS``), so ``iterations=1e8`` of 4 particles is not "4e8 evaluations, under
the cap" but what its time says. ``a`` and ``b`` come from a narrow and a wide batch of the same
steps on the paper's problem (cylindrical robot, clean eq. (39) samples, cost f13), where an
evaluation is the cheapest and a step's share the largest.

``b`` grows with the residuals an evaluation reads (samples × joints): the second table times wide
batches on 10 to 10,000 samples, whose nanoseconds per residual evaluation are
``sizes.PSO_RESIDUAL_NS`` and ``sizes.ADAM_RESIDUAL_NS`` (what a long search's notice estimates).
Each fit's ``wall_time_s`` (the kernel's one-time build excluded), the median of ``--repeat``.

    python bench/step_cost.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics

import idkit

#: (estimator, narrow options, wide options, steps option, steps)
STEP_CASES = (
    ("pso", {"runs": 1, "particles": 4}, {"runs": 1, "particles": 400}, "iterations", 20_000),
    ("adam", {"starts": 1}, {"starts": 4_000}, "steps", 500),
)
#: (estimator, wide options, steps option, evaluations per timing)
RESIDUAL_CASES = (
    ("pso", {"runs": 1, "particles": 400}, "iterations", 8_000_000),
    ("adam", {"starts": 400}, "steps", 400_000),
)
SAMPLES = (10, 1_000, 10_000)


def width(options: dict[str, int]) -> int:
    return options.get("runs", 1) * options.get("particles", 1) * options.get("starts", 1)


def seconds(name: str, options: dict[str, int], repeat: int, **study: int) -> float:
    """The median fit time (s) of ``repeat`` fits."""
    times = []
    for _ in range(repeat):
        result = idkit.run(estimator={"_name_": name, **options}, **study)
        times.append(result.estimate.wall_time_s)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    idkit.run(estimator={"_name_": "pso", "runs": 1, "particles": 4, "iterations": 10})  # kernel build
    print(f"{'estimator':9} {'width':>6} {'steps':>7} {'s':>7} {'µs/step':>9}")
    for name, narrow, wide, key, steps in STEP_CASES:
        found = []
        for options in (narrow, wide):
            t = seconds(name, {**options, key: steps}, args.repeat)
            found.append((width(options), t / steps))
            print(f"{name:9} {width(options):6} {steps:7} {t:7.3f} {1e6 * t / steps:9.2f}")
        (w1, s1), (w2, s2) = found
        per_evaluation = (s2 - s1) / (w2 - w1)
        fixed = s1 - w1 * per_evaluation
        print(
            f"{name}: a step {1e6 * fixed:.3g} µs + {1e9 * per_evaluation:.3g} ns per evaluation: "
            f"a step costs {fixed / per_evaluation:.3g} evaluations\n"
        )
    print(f"{'estimator':9} {'samples':>7} {'residuals':>9} {'steps':>7} {'s':>7} {'ns/residual':>11}")
    for name, options, key, evaluations in RESIDUAL_CASES:
        for samples in SAMPLES:
            residuals = 3 * samples  # the cylindrical robot's 3 joints
            steps = max(10, evaluations // (width(options) * samples))
            t = seconds(name, {**options, key: steps}, args.repeat, n_samples=samples)
            per_residual = t / (steps * width(options) * residuals)
            print(f"{name:9} {samples:7} {residuals:9} {steps:7} {t:7.3f} {1e9 * per_residual:11.2f}")


if __name__ == "__main__":
    main()
