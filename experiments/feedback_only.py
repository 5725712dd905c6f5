"""What the MLP adds to es's policy (the MLP plus a linear feedback path on the tracking error): copy an
``evaluate`` run's trained policies (RUN/policies/NAME) with the MLP's output layer zeroed in each policy
checkpoint (``best.pt``, else the newest), so each policy moves by its feedback path only; then evaluate the
copies with ``--checkpoints`` and compare with the run itself.

Run: python experiments/feedback_only.py --run RUN --out COPIES
then: warpcut evaluate --contours all --methods none,fixed,analytic,rl --checkpoints COPIES --trials 10
      --out EVAL --json EVAL.json --set plots=false
(RUN: a 'warpcut evaluate' run of the es learner, which trained the rl column; --contours as that run's)
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import torch

from agents.checkpoints import policy_checkpoint, read_checkpoint


def zero_mlp_output(path: Path) -> str:
    """Zero the MLP's last linear layer (weights and bias) in the checkpoint at ``path``; its name."""
    checkpoint = read_checkpoint(path)
    state = checkpoint["actor_state_dict"]
    if "mlp.feedback.weight" not in state:
        raise SystemExit(f"{path}: the actor has no feedback path (train with es: train.es.feedback=true)")
    layers = {k.rsplit(".", 1)[0] for k in state if k.startswith("mlp.body.") and k.endswith(".weight")}
    last = max(layers, key=lambda name: int(name.rsplit(".", 1)[1]))
    for key in (f"{last}.weight", f"{last}.bias"):
        state[key].zero_()
    tmp = path.with_suffix(".tmp")
    torch.save(checkpoint, tmp)
    tmp.replace(path)
    return last


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--run", type=Path, required=True, help="an evaluate run directory with policies/")
    parser.add_argument("--out", type=Path, required=True, help="where the copies go (must not exist)")
    args = parser.parse_args()
    source = args.run / "policies"
    if not source.is_dir():
        raise SystemExit(f"--run: {source} is not a directory; give an evaluate run that trained rl")
    if args.out.exists():
        raise SystemExit(f"--out: {args.out} exists; give a new directory")
    shutil.copytree(source, args.out)
    for run in sorted(p for p in args.out.iterdir() if p.is_dir()):
        checkpoint = policy_checkpoint(run)
        print(f"{run.name}: zeroed {zero_mlp_output(checkpoint)} in {checkpoint.name}")


if __name__ == "__main__":
    main()
