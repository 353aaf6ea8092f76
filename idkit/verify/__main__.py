"""``python -m idkit.verify``: run a verification tool from the shell.

python -m idkit.verify bounds [--points N]            # eq. (39) against the bounds (38)
python -m idkit.verify oracle URDF [--samples N]      # idkit's urdf robot vs the pk oracle
python -m idkit.verify cylindrical-urdf [PARAMS...]   # print the cylindrical robot as URDF
"""

from __future__ import annotations

import argparse
import sys


def _bounds(args: argparse.Namespace) -> int:
    from idkit.verify.bounds import format_violations, paper_bounds_report

    print(format_violations(paper_bounds_report(n_points=args.points)))
    return 0


def _oracle(args: argparse.Namespace) -> int:
    from pathlib import Path

    import torch

    from idkit.robots.urdf import URDFRobot
    from idkit.robots.urdf_model import ASSETS
    from idkit.seeds import torch_generator
    from idkit.verify.oracle import PKDynamics

    path = Path(args.urdf)
    if not path.is_file() and (ASSETS / f"{args.urdf}.urdf").is_file():
        path = ASSETS / f"{args.urdf}.urdf"
    robot = URDFRobot(str(path))
    oracle = PKDynamics(path, joint_names=robot.joint_names)
    gen = torch_generator(args.seed)
    n = robot.n_joints
    q, qd, qdd = (torch.randn(args.samples, n, generator=gen, dtype=torch.float64) for _ in range(3))
    ours = robot.inverse_dynamics(robot.nominal_params(), q, qd, qdd)
    reference = oracle.inverse_dynamics(q, qd, qdd)
    error = float((ours - reference).abs().max())
    print(f"{args.urdf}: max |tau_urdf - tau_oracle| = {error:.3g} N·m over {args.samples} random states")
    return 0 if error <= args.tolerance else 1


def _cylindrical(args: argparse.Namespace) -> int:
    from idkit.verify.cylindrical_urdf import cylindrical_urdf

    sys.stdout.write(cylindrical_urdf(args.params) if args.params else cylindrical_urdf())
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m idkit.verify",
        description="Independent references that check idkit's models (see idkit.verify).",
        epilog=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="tool", required=True)
    bounds = sub.add_parser("bounds", help="where eq. (39) leaves the bounds (38)")
    bounds.add_argument("--points", type=int, default=10001, help="grid points over 0..10 s")
    bounds.set_defaults(run=_bounds)
    oracle = sub.add_parser("oracle", help="compare the urdf robot with the pytorch-kinematics oracle")
    oracle.add_argument("urdf", help="URDF file (or a shipped asset name, e.g. cylindrical)")
    oracle.add_argument("--samples", type=int, default=100)
    oracle.add_argument("--seed", type=int, default=0)
    oracle.add_argument("--tolerance", type=float, default=1e-9, help="exit 1 above this (N·m)")
    oracle.set_defaults(run=_oracle)
    cyl = sub.add_parser("cylindrical-urdf", help="print the cylindrical robot as URDF")
    cyl.add_argument("params", nargs="*", type=float, help="m2 m3 s3z I (default: the paper's values)")
    cyl.set_defaults(run=_cylindrical)
    args = parser.parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
