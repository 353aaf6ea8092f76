"""idkit.testing."""
