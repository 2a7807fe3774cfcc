"""Hook implementations of the flag plugin (cheap to import: names only)."""

from physinfer.hooks import hookimpl


@hookimpl
def physinfer_register_phenomena(registry):
    registry.add_phenomenon(
        "flag", "physinfer_flag.phenomenon:make_phenomenon", "a flag waving in the wind (the paper's case)"
    )
