"""The ``physinfer`` command line."""

def main() -> None:
    from physinfer.cli.app import run

    run()
