"""Verification tools: independent references that check idkit's models, not needed to identify a robot.

* :mod:`idkit.verify.oracle` — inverse dynamics of any URDF from pytorch-kinematics Jacobians and the
  Euler–Lagrange equations (no recursive Newton–Euler), the oracle for ``cylindrical`` and ``urdf``;
* :mod:`idkit.verify.cylindrical_urdf` — the paper's cylindrical robot rendered as URDF for any
  parameters (the shipped ``robots/assets/cylindrical.urdf`` is its output at the true values);
* :mod:`idkit.verify.bounds` — where an excitation trajectory leaves a box such as eq. (38);
* :mod:`idkit.verify.rescore` — a written ``identified.urdf`` re-scored with pinocchio under the
  documented held-out metric or a classic pipeline (the check on idkit's reported figure).

Command line: ``python -m idkit.verify --help``.
"""
