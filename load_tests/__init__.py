"""Load, soak and fault tests, and benchmarks that print JSON."""
