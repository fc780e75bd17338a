"""Device interfaces (one small ABC per device kind) and the backend registry."""
