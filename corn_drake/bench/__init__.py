"""Benchmarks run by `corn-drake bench <what>`; one module per benchmark.

`corn-drake bench` imports every module here to build its parser, so a module's top level
imports no numpy, torch, Drake or tqdm: they go inside the functions that use them, and
`corn-drake --help` answers at once (tests/test_cli_startup.py checks it).
"""
