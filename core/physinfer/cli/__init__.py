"""The ``physinfer`` command line."""

from physinfer.cli.app import run


def main() -> None:
    run()
