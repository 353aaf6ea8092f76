"""Studies: computation only. Each task is one function returning a result object.

``single.run`` (one fit), ``paper.run`` (Tables II–V), ``robustness.run`` (Monte-Carlo study),
``kuka.run`` (a real robot, held-out torques). A study builds plugins from specs (``build``), labels
estimates (``labels``), and returns a result carrying the common envelope (``result.Provenance``)
and a task-specific ``payload()``. It never formats text or writes files: ``idkit.reports`` does.
"""
