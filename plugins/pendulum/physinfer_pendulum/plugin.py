"""Hook implementations of the pendulum plugin.

This module is all physinfer imports to discover the plugin, so it names its
implementations as ``"module:attr"`` strings instead of importing them.
"""

from physinfer.hooks import hookimpl


@hookimpl
def physinfer_register_phenomena(registry):
    registry.add_phenomenon(
        "pendulum", "physinfer_pendulum.phenomenon:make_phenomenon", "a bob on a string, measured from real footage"
    )


@hookimpl
def physinfer_register_effects(registry):
    registry.add_effect(
        "air_drag",
        "physinfer_pendulum.physics:QuadraticDrag",
        phenomenon="pendulum",
        description="air drag growing with the square of the bob's speed",
    )
