"""Benchmarks: `make bench` (python -m bench [--only NAME ...] [--skip NAME ...])."""
