"""The solution methods, one per module, and their registry by name."""
