"""One module per `corn-drake` subcommand (see corn_drake/cli.py)."""
