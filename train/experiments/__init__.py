"""Small environments and experiment helpers for the training package."""
