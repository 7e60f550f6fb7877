"""Benchmarks: each `twin bench NAME` lives in its own module here and prints a table.

Not installed with twin: `twin bench` finds this folder beside the `twin` package of a source checkout.
"""
