"""Benchmarks: each `twin bench NAME` lives in its own module here and prints a table."""
