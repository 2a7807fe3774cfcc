# %% [markdown]
# # physinfer from Python: refine a pendulum and a flag, read the intervals, plot
#
# A notebook in the percent format (open it in Jupyter with jupytext, or in VS Code, or run
# it as a script: `python examples/notebook_refine.py --out runs/notebook`). Every cell uses
# `physinfer.api`, the layer the CLI stands on: the keyword arguments are the CLI's options.
# `--steps N` shortens both refinements and `--plugins pendulum` skips the flag (the tests
# run it so).

# %%
import argparse
import sys
from pathlib import Path

import physinfer as pi

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=Path("runs/notebook"))
parser.add_argument("--steps", type=int, default=None, help="trials per refinement")
parser.add_argument("--plugins", default="pendulum,flag", help="which of the two to refine")
args, _ = parser.parse_known_args(sys.argv[1:])  # a notebook kernel passes its own arguments
args.out.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## A pendulum: simulate a target, refine, compare with the truth

# %%
truth = {"length": 1.3, "damping": 0.2, "amplitude": 40.0}
target = pi.simulate("pendulum_lab", set=truth, seed=7, out=args.out / "pendulum_target.mp4")
target.plot(n=5).savefig(args.out / "pendulum_frames.png")

pendulum = pi.refine(
    "pendulum_lab",
    target=args.out / "pendulum_target.mp4",
    truth=truth,
    steps=args.steps or 20,
    out=args.out / "pendulum_lab",
    overwrite=True,
)
for name, value in pendulum.best_params.items():
    print(f"pendulum {name}: {value:.3f} (truth {truth[name]})")
pendulum.plot().savefig(args.out / "pendulum_refinement.png")

# %% [markdown]
# ## The flag: the embedded target, with the shipped posterior
#
# The posterior says what the video determines: the wind is identified, the bending
# multipliers are not. Options can be kept in one object and varied with keywords.

# %%
if "flag" not in args.plugins.split(","):
    sys.exit(0)
flag_options = pi.RefineOptions(steps=args.steps or 16, batch_size=4)
flag = pi.refine("flag", flag_options, out=args.out / "flag", overwrite=True)
for name, marginal in flag.posterior.items():
    if marginal["label"] != "not identified":
        lo, hi = marginal["ci90"]
        print(f"flag {name}: {marginal['median']:.3f}  [90 %: {lo:.3f} – {hi:.3f}]  {marginal['label']}")
flag.plot(max_params=4).savefig(args.out / "flag_refinement.png")
print("results in", flag.run_dir)
