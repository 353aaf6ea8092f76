"""The robot as the simulator sees it: MuJoCo models, their settable quantities and batched rollouts.

What rollout identification (``estimator=rollout``, :mod:`idkit.estimators.rollout`) builds on: a model
(:mod:`~idkit.sim.model`), the quantities it can set and the unknowns chosen from them
(:mod:`~idkit.sim.quantities`, :mod:`~idkit.sim.inertia`), the sample-time convention
(:mod:`~idkit.sim.timing`), which command drives which actuator (:mod:`~idkit.sim.drive`), segments
(:mod:`~idkit.sim.segments`, :mod:`~idkit.sim.initial`), batched rollouts (:mod:`~idkit.sim.simulate`),
the problem and its error (:mod:`~idkit.sim.problem`), the polish's residuals
(:mod:`~idkit.sim.shooting`), uncertainty (:mod:`~idkit.sim.uncertainty`), held-out validation on the
fit's horizon (:mod:`~idkit.sim.validation`) and ``identified.xml`` (:mod:`~idkit.sim.export`).
Nothing here imports an estimator, a study or a report (``tests/test_layout.py``).
"""
