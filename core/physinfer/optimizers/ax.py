"""Bayesian optimisation with Ax's ``Client``: a GP with a Matérn-5/2 kernel (the paper's choice).

The generation strategy is Sobol initialisation followed by BoTorch's modular GP
(``SingleTaskGP`` with a scaled ARD Matérn-5/2 kernel) and Ax's default acquisition
(log noisy expected improvement). The centre trial is attached by the loop, not
generated, so every optimizer starts there alike.
"""

from __future__ import annotations

import logging

import numpy as np

from physinfer.roles import Optimizer, Trial

METRIC = "distance"


def _quiet_ax() -> None:
    """Silence Ax's per-trial INFO logging (it sets levels on each module logger)."""
    for name in list(logging.Logger.manager.loggerDict):
        if name.split(".")[0] in ("ax", "botorch", "gpytorch", "linear_operator"):
            logging.getLogger(name).setLevel(logging.WARNING)
    # Once the GP has converged in a small space (e.g. wind and area weight with the
    # bending held by --fix) it proposes points already tried; Ax then draws a Sobol point
    # instead and warns on every step. That fallback is the right move (a repeated θ would
    # repeat its distance), so the warning is noise to a user.
    node_logger = logging.getLogger("ax.generation_strategy.generation_node")
    if not any(isinstance(f, _DropDuplicateFallback) for f in node_logger.filters):
        node_logger.addFilter(_DropDuplicateFallback())
    import warnings

    warnings.filterwarnings("ignore", module="(ax|botorch|gpytorch|linear_operator).*")
    # BoTorch re-issues a failed GP-fit step with warn_explicit, whose "module" is the file's
    # full path, which the filter above does not match. The fit goes on from its best state
    # (and a fit that fails outright is handled below), so for a user it is noise.
    warnings.filterwarnings("ignore", message="`scipy_minimize` terminated with status")


class _DropDuplicateFallback(logging.Filter):
    """Drops Ax's "exceeded MAX_GEN_ATTEMPTS ... switching to fallback" warning."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "MAX_GEN_ATTEMPTS" not in record.getMessage()


#: Exceptions of a failed GP fit or acquisition optimisation (BoTorch, GPyTorch,
#: linear_operator), matched by name so that importing this module does not import them.
#: ``OptimizationGradientError`` (NaN acquisition gradients) was seen on a flag target with
#: ``--batch-size 4``, asking for trials 17–20 (reproduced: held-out target 15 of bench_refine).
_GP_FAILURES = frozenset({"ModelFittingError", "NotPSDError", "NanError", "OptimizationGradientError"})
#: The same failure raised by torch itself: NaN acquisition values reach the multinomial draw of
#: BoTorch's initial conditions (flag_lite's wind_inclination stage after 6 trials, wind_yaw 0.15, seed 100,
#: 2026-11-27: "probability tensor contains either `inf`, `nan` or element < 0").
_NAN_DRAW = "probability tensor contains"


def _gp_failure(exc: Exception) -> bool:
    """Whether ``exc`` is a failed GP fit or acquisition optimisation (not a bug of ours)."""
    return type(exc).__name__ in _GP_FAILURES or (isinstance(exc, RuntimeError) and _NAN_DRAW in str(exc))


class AxOptimizer(Optimizer):
    """Ask/tell over ``[-1, 1]^D`` with an Ax ``Client``.

    Args:
        dim: Number of parameters ``D``.
        seed: Seed of Sobol initialisation and acquisition optimisation.
        names: Parameter names (shown in Ax's own summaries).
        n_init: Sobol trials before the GP takes over (the attached centre counts).
        kernel: ``"matern52"`` (default, as the paper) or ``"ax_default"``.
    """

    def __init__(
        self,
        *,
        dim: int,
        seed: int = 0,
        names: list[str] | None = None,
        n_init: int = 6,
        kernel: str = "matern52",
    ) -> None:
        super().__init__(dim=dim, seed=seed, names=names)
        from ax.api.client import Client
        from ax.api.configs import RangeParameterConfig

        _quiet_ax()

        self._client = Client(random_seed=seed)
        self._client.configure_experiment(
            parameters=[
                RangeParameterConfig(name=n, bounds=(-1.0, 1.0), parameter_type="float") for n in self.names
            ],
            name="physinfer",
        )
        self._client.configure_optimization(objective=f"-{METRIC}")
        self._client.set_generation_strategy(self._strategy(n_init, kernel))
        self.fallbacks = 0

    def _strategy(self, n_init: int, kernel: str):  # noqa: ANN202 - Ax type
        from ax.api.utils.generation_strategy_dispatch import choose_generation_strategy
        from ax.api.utils.structs import GenerationStrategyDispatchStruct

        struct = GenerationStrategyDispatchStruct(
            method="custom" if kernel == "matern52" else "fast",
            initialization_budget=n_init,
            initialization_random_seed=self.seed,
            initialize_with_center=False,
            use_existing_trials_for_initialization=True,
            min_observed_initialization_trials=min(n_init, 2),
            allow_exceeding_initialization_budget=True,
        )
        if kernel != "matern52":
            return choose_generation_strategy(struct=struct)
        from ax.generators.torch.botorch_modular.utils import ModelConfig
        from botorch.models import SingleTaskGP
        from gpytorch.kernels import MaternKernel, ScaleKernel

        config = ModelConfig(
            botorch_model_class=SingleTaskGP,
            covar_module_class=ScaleKernel,
            covar_module_options={"base_kernel": MaternKernel(nu=2.5, ard_num_dims=self.dim)},
            name="GP-Matern52",
        )
        return choose_generation_strategy(struct=struct, model_config=config)

    def _params(self, x: np.ndarray) -> dict[str, float]:
        return {n: float(np.clip(v, -1.0, 1.0)) for n, v in zip(self.names, x, strict=True)}

    def ask(self, n: int = 1) -> list[Trial]:
        """Ax's next ``n`` trials; random points where the GP cannot be fitted or its
        acquisition cannot be optimised.

        BoTorch gives up fitting the GP now and then (seen on a chaotic flag target after
        30 trials with a measured observation noise), and a joint batch acquisition can hit
        NaN gradients; one such step should not end a run of many minutes, so it falls back
        to uniform draws, each seeded by (seed, trial count) so a resumed run draws the
        same, and ``fallbacks`` counts them.
        """
        try:
            proposals = self._client.get_next_trials(max_trials=n)
        except Exception as exc:
            if not _gp_failure(exc):
                raise
            return [self._fallback_trial() for _ in range(n)]
        _quiet_ax()  # modules imported lazily during the first GP fit log again
        return [
            Trial(idx, np.array([float(p[name]) for name in self.names])) for idx, p in sorted(proposals.items())
        ]

    def _fallback_trial(self) -> Trial:
        self.fallbacks += 1
        n_trials = len(self._client._experiment.trials)
        rng = np.random.default_rng([self.seed, n_trials, 0xFA11])
        return self.attach(rng.uniform(-1.0, 1.0, self.dim))

    def attach(self, x: np.ndarray) -> Trial:
        idx = self._client.attach_trial(parameters=self._params(np.asarray(x, dtype=float)))
        return Trial(idx, np.asarray(x, dtype=float))

    def tell(self, index: int, value: float | None, sem: float | None = None) -> None:
        if value is None or not np.isfinite(value):
            self._client.mark_trial_failed(trial_index=index)
            return
        raw = (float(value), float(sem)) if sem is not None else float(value)
        self._client.complete_trial(trial_index=index, raw_data={METRIC: raw})
