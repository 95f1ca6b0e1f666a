"""Studies outside the package: each topic folder holds scripts that measured something and a
README with what each measured, its result and the command that reruns it. They import
corn_drake like any user; corn_drake never imports them (tests/test_architecture.py)."""
