"""Benchmarks and accuracy reports run by `make bench` and `make accuracy`."""
