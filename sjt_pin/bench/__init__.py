"""Benchmarks of ``sjt-pin bench``: step speed, accuracy near singularities, solve to a pose."""
