"""Array-level optimisers: the particle swarm and its fast compiled kernel, and a robust polish.

Nothing here knows a robot, a ``Problem`` or an estimator: the swarm (``swarm``) minimises any
``cost[..., K]`` of ``positions[..., K, P]`` in a box, and the fast engine (``fast``, on the kernel
in ``kernel``) minimises a ``fast.ProductSpec`` — products of factors of an error affine in the base
parameters — given as arrays. ``blocks`` runs one swarm per block of coordinates on a cost made of
parts, ``levenberg`` is a bounded Levenberg–Marquardt that eliminates nuisance blocks, and ``robust``
holds its losses and the scale that sets itself (rollout identification uses all three). The PSO
estimator, excitation design and anything else with such an objective build on it;
``tests/test_layout.py`` keeps estimators out of this package.
"""
