"""physinfer's built-in plugin: the optimizers and the generic spectral embedder.

Registered through the ``physinfer`` entry-point group like any third-party plugin.
"""

from __future__ import annotations

from physinfer.hooks import hookimpl
from physinfer.registry import Registry


@hookimpl
def physinfer_register_optimizers(registry: Registry) -> None:
    registry.add_optimizer("ax", "physinfer.optimizers.ax:AxOptimizer", "Bayesian optimisation (Ax, GP with Matérn-5/2)")
    registry.add_optimizer("random", "physinfer.optimizers.random:RandomOptimizer", "uniform random search")
    registry.add_optimizer("cma", "physinfer.optimizers.cma:CMAOptimizer", "CMA-ES (pycma)")


@hookimpl
def physinfer_register_embedders(registry: Registry) -> None:
    registry.add_embedder(
        "grid_spectrum",
        "physinfer.embedders:GridSpectrumEmbedder",
        "parameter-free: pixel spectra pooled over a grid (any phenomenon)",
    )
    registry.add_embedder(
        "motion",
        "physinfer.embedders:MotionSpectrumEmbedder",
        "parameter-free: spectra of the tracked path of what moves (looks left out; real footage)",
    )


@hookimpl
def physinfer_register_commands(registry: Registry) -> None:
    registry.add_command(
        "dataset",
        "physinfer.cli.dataset_cmd:dataset_app",
        "Generate training datasets of simulated, rendered clips.",
    )
    registry.add_command(
        "diagnose",
        "physinfer.cli.diagnose_cmd:diagnose_cmd",
        "Find where a refined model disagrees with the video and name the missing effect.",
    )
    registry.add_command(
        "render",
        "physinfer.cli.render_cmd:render_cmd",
        "Render a trajectory file (physinfer NPZ or per-frame OBJ meshes) with a phenomenon's renderer.",
    )
    registry.add_command(
        "prepare",
        "physinfer.cli.prepare_cmd:prepare_cmd",
        "Find the moving subject in a video, steady the camera, crop to the renderer's framing, resample.",
    )
    registry.add_command(
        "posterior",
        "physinfer.cli.posterior_cmd:posterior_app",
        "Amortized posteriors over θ: train an estimator on a dataset (sbi).",
    )
    registry.add_command(
        "infer",
        "physinfer.cli.posterior_cmd:infer_cmd",
        "The posterior of one video in seconds: medians, credible intervals, identifiability.",
    )
    registry.add_command(
        "report",
        "physinfer.cli.report_cmd:report_cmd",
        "Rebuild a run's self-contained report.html (parameters, plots, video, settings).",
    )
    registry.add_command(
        "evaluate calibration",
        "physinfer.cli.posterior_cmd:calibration_cmd",
        "Simulation-based calibration of a posterior estimator on held-out simulations.",
    )
