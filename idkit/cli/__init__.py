"""idkit.cli."""
