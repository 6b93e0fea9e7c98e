"""Benchmarks: commands that measure speed and memory (never timing assertions in tests)."""
