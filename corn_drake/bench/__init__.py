"""Benchmarks run by `corn-drake bench <what>`; one module per benchmark."""
