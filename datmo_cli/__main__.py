"""`python -m datmo_cli`: the same as the `datmo` command."""

from .cli import main

main()
