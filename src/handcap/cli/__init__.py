"""The ``handcap`` command: one module per group of verbs, each parsing arguments and calling the library."""

from handcap.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
