"""idkit-robust: third-party idkit plugins, registered through entry points only.

* robot ``planar2`` (``idkit_robust.planar2``): a 2-link arm in the vertical plane;
* costs ``huber`` and ``trimmed`` (``idkit_robust.costs``): robust costs of the error matrix;
* estimator ``irls`` (``idkit_robust.irls``): iteratively reweighted least squares.

Nothing here is imported by idkit itself; ``idkit.registry`` finds the names in this
distribution's metadata.
"""

__version__ = "0.1.0"
