"""Benchmarks (imported only by the CLI)."""
