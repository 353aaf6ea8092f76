"""idkit.experiments."""
