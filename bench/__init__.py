"""Benchmarks of the lookahead planners (run from the repository root; see README.md)."""
