"""The convex toolbox of physically consistent identification: one program, several users.

``pcls`` (:mod:`idkit.estimators.physical`), its cross-validated prior weight, ``varpro``'s
refinement, the projection :func:`~idkit.conic.program.nearest_consistent` and the payload fit
(:mod:`idkit.estimators.payload`) all solve least squares under the same constraints:

* :mod:`idkit.conic.prior` — the CAD reference bodies, made well-posed where the URDF's are
  degenerate (thin rods, flat discs, point masses) or impossible;
* :mod:`idkit.conic.plausible` — bounds that keep links plausible, not only consistent (mass
  bounds relative to CAD, a known total mass, the centre of mass and the mass inside the link's
  geometry) and the one per-link plausibility verdict every report reads;
* :mod:`idkit.conic.program` — the semidefinite program itself, its scaling, the solver chain and
  the checks that make its guarantees independent of a solver's last digits.

Nothing here is an estimator: this package imports robots and problems, never an estimator, a study
or a report (``tests/test_layout.py``).
"""
