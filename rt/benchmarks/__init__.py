"""Benchmarks the product ships as commands (`talus bench ...`): figures, not pass/fail."""
