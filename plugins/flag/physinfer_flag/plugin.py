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
    registry.add_embedder(
        "spectral_shape",
        "physinfer_flag.sdn.embedder:spectral_shape_embedder",
        "spectral + the clip's mean image (experimental: sees wind direction better, fits worse; see docs)",
    )


@hookimpl
def physinfer_register_commands(registry):
    registry.add_command(
        "train", "physinfer_flag.cli:train_cmd", "Train the flag's SDN embedding on a generated dataset."
    )
    registry.add_command(
        "evaluate triplets",
        "physinfer_flag.cli:evaluate_triplets_cmd",
        "Triplet accuracy of the SDN (or the spectral baseline) on a dataset's test split.",
    )
    registry.add_command(
        "evaluate wind",
        "physinfer_flag.cli:evaluate_wind_cmd",
        "Wind-speed regression (MSE, Acc@0.5) of the SDN or a baseline on a dataset's test split.",
    )


@hookimpl
def physinfer_register_effects(registry):
    registry.add_effect(
        "wind_gusts", "physinfer_flag.effects:WindGusts", phenomenon="flag",
        description="turbulent fluctuation of the wind speed (gusts)",
    )
    registry.add_effect(
        "wind_shear", "physinfer_flag.effects:WindShear", phenomenon="flag",
        description="vertical wind shear: wind speed rising with height (power law)",
    )
    registry.add_effect(
        "wind_yaw", "physinfer_flag.effects:WindYaw", phenomenon="flag",
        description="wind direction offset (yaw) from the assumed direction",
    )
    registry.add_effect(
        "wind_inclination", "physinfer_flag.effects:WindInclination", phenomenon="flag",
        description="vertical inclination of the wind (updraft or downdraft)",
    )
