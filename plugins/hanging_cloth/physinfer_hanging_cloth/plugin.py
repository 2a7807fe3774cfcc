"""Hook implementations of the hanging-cloth plugin (cheap to import: names only)."""

from physinfer.hooks import hookimpl


@hookimpl
def physinfer_register_phenomena(registry):
    registry.add_phenomenon(
        "hanging_cloth",
        "physinfer_hanging_cloth.phenomenon:make_phenomenon",
        "a fabric hanging from a rod in front of a fan (Bouman et al. 2013)",
    )


@hookimpl
def physinfer_register_commands(registry):
    registry.add_command(
        "evaluate bouman",
        "physinfer_hanging_cloth.cli:evaluate_bouman_cmd",
        "Bouman et al. hanging-fabric evaluation: PCA + linear regression, leave one fabric out, Pearson R.",
    )
    registry.add_command(
        "dataset bouman",
        "physinfer_hanging_cloth.cli:dataset_bouman_cmd",
        "Write a synthetic hanging-cloth dataset in the Bouman format (fabrics x fan levels W1-W3).",
    )
