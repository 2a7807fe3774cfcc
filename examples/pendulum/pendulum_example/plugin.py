"""Hook implementations of the pendulum example.

This module is all physinfer imports to discover the plugin, so it names its
implementations as ``"module:attr"`` strings instead of importing them.
"""

from physinfer.hooks import hookimpl


@hookimpl
def physinfer_register_phenomena(registry):
    registry.add_phenomenon(
        "pendulum_lab", "pendulum_example.phenomenon:make_phenomenon", "the lab pendulum: a synthetic damped pendulum (worked example)"
    )


@hookimpl
def physinfer_register_effects(registry):
    registry.add_effect(
        "quadratic_drag",
        "pendulum_example.physics:QuadraticDrag",
        phenomenon="pendulum_lab",
        description="air drag growing with the square of the bob's speed",
    )
