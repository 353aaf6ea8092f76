"""What biased the README tour's friction and offsets? One factor at a time, on its simulated arm.

Run: ``python bench/tour_bias.py``.

The tour's ``train.csv`` (``tests/tour_cases.py``: its optimised motion at 200 Hz, the arm with its
truth) is fitted by plain least squares on the robot's base regressor, changing one thing at a time:
exact states and torques; the recording preprocessed (resampled, low-passed, differentiated) at a
fixed cut-off with and without filtering the torques; encoder noise alone; torque noise alone; both.
Prints one Markdown table of the relative error of each friction, offset and link2's mass.
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/tour_cases.py

from idkit.data.preprocess import PreprocessOptions, preprocess  # noqa: E402
from idkit.data.recording import Recording  # noqa: E402
from tests import tour_cases  # noqa: E402

SHOWN = ["theta1.fc", "d2.fc", "d3.fc", "theta1.fv", "d2.fv", "d3.fv", "d2.offset", "d3.offset", "link2.m"]


def main() -> None:
    torch.set_num_threads(1)
    warnings.simplefilter("ignore", UserWarning)
    urdf = tour_cases.tour_urdf(Path(tempfile.mkdtemp()))
    robot = tour_cases.tour_robot(urdf)
    params = tour_cases.true_params(robot)
    truth = robot.base_params(params).numpy()
    names = list(robot.base_param_names)
    t, q, qd, qdd = tour_cases.tour_motion(urdf)
    tau = robot.inverse_dynamics(params, *(torch.from_numpy(x) for x in (q, qd, qdd))).numpy()
    rng = np.random.default_rng(0)
    encoder = q + 1e-4 * rng.standard_normal(q.shape)
    noisy_tau = tau + 0.01 * tau.std(0) * rng.standard_normal(tau.shape)

    def fit(states: tuple[np.ndarray, ...], torques: np.ndarray) -> np.ndarray:
        W = robot.regressor(*(torch.from_numpy(np.ascontiguousarray(x)) for x in states)).numpy()
        return np.linalg.lstsq(W.reshape(-1, len(names)), torques.reshape(-1), rcond=None)[0]

    def preprocessed(positions: np.ndarray, torques: np.ndarray, **options) -> np.ndarray:
        recording = Recording(t, positions, torques, joint_names=robot.joint_names)
        s = preprocess(recording, PreprocessOptions(**options))
        return fit((s.q.numpy(), s.qd.numpy(), s.qdd.numpy()), s.tau.numpy())

    cases = [("exact states and torques", fit((q, qd, qdd), tau))]
    for filtered in (True, False):
        for cutoff in (2.0, 4.0, 10.0):
            label = f"noise-free, {cutoff:g} Hz, torques {'filtered' if filtered else 'unfiltered'}"
            cases.append((label, preprocessed(q, tau, cutoff=cutoff, filter_torques=filtered)))
    cases += [
        ("exact states, torque noise", fit((q, qd, qdd), noisy_tau)),
        ("encoder noise only, 4 Hz, unfiltered", preprocessed(encoder, tau, cutoff=4.0)),
        ("torque noise only, 4 Hz, unfiltered", preprocessed(q, noisy_tau, cutoff=4.0)),
        (
            "both noises, 4 Hz, torques filtered",
            preprocessed(encoder, noisy_tau, cutoff=4.0, filter_torques=True),
        ),
        ("both noises, 4 Hz, unfiltered", preprocessed(encoder, noisy_tau, cutoff=4.0)),
        ("both noises, 10 Hz, unfiltered", preprocessed(encoder, noisy_tau, cutoff=10.0)),
    ]
    print("| case | " + " | ".join(f"`{n}`" for n in SHOWN) + " |")
    print("|---|" + "---:|" * len(SHOWN))
    for label, alpha in cases:
        error = [
            100 * (alpha[names.index(n)] - truth[names.index(n)]) / abs(truth[names.index(n)]) for n in SHOWN
        ]
        print(f"| {label} | " + " | ".join(f"{e:+.2f} %" for e in error) + " |")


if __name__ == "__main__":
    main()
