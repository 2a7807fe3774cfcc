"""Hook implementations of the flag plugin (cheap to import: names only)."""

from physinfer.hooks import hookimpl


@hookimpl
def physinfer_register_phenomena(registry):
    registry.add_phenomenon(
        "flag", "physinfer_flag.phenomenon:make_phenomenon", "a flag waving in the wind (the paper's case)"
    )


@hookimpl
def physinfer_register_embedders(registry):
    registry.add_embedder(
        "sdn", "physinfer_flag.sdn.embedder:SDNEmbedder", "Spectral Decomposition Network (learned, torch)"
    )
    registry.add_embedder(
        "spectral", "physinfer_flag.sdn.embedder:SpectralEmbedder", "SDN front end + pooling (parameter-free, torch)"
    )
