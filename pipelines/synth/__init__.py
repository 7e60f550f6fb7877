"""Synthetic samples and benchmark data with known truth."""
