"""Guided policy search with closed-loop teachers near the student: per-contour policies fine-tuned from the
shipped generalist (``train --set init=generalist``: where it plays, its moves halved), distilled back into
one student by DAgger, to play with ``--generalist DIR``.

``teachers``: for each of the first N contours of the generated ``train`` stream (seed 0), es fine-tuned
from the generalist for ``--iterations`` (a run directory each; a finished one is kept, so the stage
resumes). ``distill``: every teacher's contour is cut by ``--envs`` envs at its teacher's cut; each round
the student (or, with probability ``beta0 / 2**round``, the teacher) plays one episode, every state the
student visits is labelled with its teacher's move there, the labels of all rounds are kept, and the
student regresses onto them (``--epochs`` passes, Adam). The student starts from the shipped generalist or,
with ``--hidden``, from a fresh MLP of those widths with the generalist's observation normaliser; it is
written as a generalist directory (``best.pt``, ``generalist.json``). Then play it on contours none of the
teachers cut, e.g. ``warpcut evaluate --contours gen-validation-0:16 --methods none,fixed,generalist
--generalist DIR``.

Run: python experiments/distill_fine_tuned.py teachers --count 32 --iterations 10 --out TEACHERS
     python experiments/distill_fine_tuned.py distill --teachers TEACHERS --hidden 256,256 --rounds 12 \
         --epochs 25 --out STUDENT
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import time
from pathlib import Path

import numpy as np


def teachers(args) -> None:
    from agents.config import TrainConfig
    from agents.generalist import SHIPPED_DIR
    from agents.jobs import TrainJob, with_dependent_defaults
    from agents.training import train_contour
    from warpcut.planning.generate import generate_contours
    from warpcut.sim.config import SimConfig

    train = dataclasses.replace(TrainConfig(algo="es"), iterations=args.iterations)
    for contour in generate_contours(args.count, "train", 0, SimConfig()):
        out = args.out / contour.name
        if (out / "summary.json").is_file():
            continue
        started = time.monotonic()
        job = TrainJob(contour=contour.name, train=train, plots=False, init=str(SHIPPED_DIR), eval_trials=2)
        train_contour(with_dependent_defaults(job, set()), out, progress=False)
        errors = [round(v["error"], 2) for v in json.loads((out / "summary.json").read_text())["validation"]]
        print(f"{contour.name}: validation {errors} ({time.monotonic() - started:.0f} s)", flush=True)


def _student(generalist, hidden: list[int] | None, state: dict):
    """The student to train and its checkpoint's policy description."""
    import torch
    from rsl_rl.utils import resolve_callable
    from tensordict import TensorDict

    if not hidden:
        return copy.deepcopy(generalist.actor), state["policy"]
    policy = copy.deepcopy(state["policy"])
    policy["actor"]["hidden_dims"] = hidden
    actor_cfg = dict(policy["actor"])
    actor_class = resolve_callable(actor_cfg.pop("class_name"))
    obs = TensorDict({k: torch.zeros(1, *v) for k, v in policy["obs_shapes"].items()}, batch_size=[1])
    student = actor_class(obs, policy["obs_groups"], "actor", policy["num_actions"], **actor_cfg)
    normaliser = {k: v for k, v in generalist.actor.state_dict().items() if k.startswith("obs_normalizer")}
    student.load_state_dict(normaliser, strict=False)
    return student, policy


def distill(args) -> None:
    import torch
    from tensordict import TensorDict

    from agents.generalist import SHIPPED_DIR, generalist_options, load_generalist
    from agents.policies import load_options, load_policy
    from envs.options import EnvConfig
    from envs.vector import PatternCutVecEnv
    from warpcut.sim.config import SimConfig

    torch.manual_seed(0)
    generalist = load_generalist(str(SHIPPED_DIR))
    acting_in = EnvConfig(**generalist.settings["env"])
    runs = sorted(d for d in args.teachers.iterdir() if (d / "summary.json").is_file())
    contours, pinches, cuts, policies = [], [], [], []
    for run in runs:
        options = load_options(run)
        contours.append(options.contours(1)[0])
        pinches.append(np.asarray(options.pinch_point, dtype=np.float64).reshape(-1)[:2])
        cuts.append([np.asarray(s) for s in options.segments])
        policies.append(load_policy(run, acting_in))
    options = generalist_options(generalist, contours, pinches, cuts, SimConfig(), trials=args.envs)
    env = PatternCutVecEnv(len(contours) * args.envs, options)
    state = torch.load(SHIPPED_DIR / "best.pt", weights_only=False)
    student, policy = _student(generalist, args.hidden, state)
    student.train()
    student.obs_normalizer.eval()  # the generalist's, as it is
    weights = [p for name, p in student.named_parameters() if name.startswith("mlp.")]
    optimiser = torch.optim.Adam(weights, lr=args.lr)
    n, owner, rng = env.num_envs, np.repeat(np.arange(len(contours)), args.envs), np.random.default_rng(0)
    inputs, labels = [], []

    def batch(obs: torch.Tensor) -> TensorDict:
        return TensorDict({"policy": obs}, batch_size=[len(obs)])

    for round_ in range(args.rounds):
        started = time.monotonic()
        by_teacher = torch.as_tensor(rng.random(n) < args.beta0 * 0.5**round_)[:, None]
        obs, _ = env.reset(seed=1000 + round_)
        with torch.inference_mode():
            for _ in range(env.task.num_steps):
                obs = torch.as_tensor(obs)
                move = student(batch(obs)).reshape(n, -1)
                label = torch.zeros_like(move)
                for k, teacher in enumerate(policies):
                    envs = np.nonzero(owner == k)[0]
                    label[envs] = teacher(batch(obs[envs])).reshape(len(envs), -1)
                inputs.append(obs.clone())
                labels.append(label.clone())
                played = torch.where(by_teacher, label, move).numpy()
                obs, _, terminated, truncated, info = env.scene.step(played)
                if terminated or truncated:
                    break
        x, y = torch.cat(inputs), torch.cat(labels)
        loss = 0.0
        for _ in range(args.epochs):
            order, loss = torch.randperm(len(x)), 0.0
            for start in range(0, len(x), 4096):
                at = order[start : start + 4096]
                error = ((student(batch(x[at])).reshape(len(at), -1) - y[at]) ** 2).mean()
                optimiser.zero_grad()
                error.backward()
                optimiser.step()
                loss += float(error.detach()) * len(at)
        print(
            f"round {round_}: the episode's error {np.mean(info['error_vertices']):.2f} vertices, {len(x)} "
            f"states, loss {loss / len(x):.4f} ({time.monotonic() - started:.0f} s)",
            flush=True,
        )
    args.out.mkdir(parents=True, exist_ok=True)
    settings = json.loads((SHIPPED_DIR / "generalist.json").read_text())
    if args.hidden:
        settings["policy"]["actor_hidden_dims"] = args.hidden
    settings["command"] = None
    (args.out / "generalist.json").write_text(json.dumps(settings, indent=2))
    student.eval()
    torch.save({**state, "policy": policy, "actor_state_dict": student.state_dict()}, args.out / "best.pt")
    print(f"wrote {args.out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    stages = parser.add_subparsers(dest="stage", required=True)
    make = stages.add_parser("teachers")
    make.add_argument("--count", type=int, default=32)
    make.add_argument("--iterations", type=int, default=10)
    make.add_argument("--out", type=Path, required=True)
    learn = stages.add_parser("distill")
    learn.add_argument("--teachers", type=Path, required=True)
    learn.add_argument("--envs", type=int, default=4, help="envs a teacher's contour")
    learn.add_argument("--rounds", type=int, default=12)
    learn.add_argument("--epochs", type=int, default=25)
    learn.add_argument("--lr", type=float, default=1e-3)
    learn.add_argument("--beta0", type=float, default=1.0, help="the teacher's share of the first round")
    learn.add_argument("--hidden", type=lambda s: [int(v) for v in s.split(",")], default=None)
    learn.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    teachers(args) if args.stage == "teachers" else distill(args)


if __name__ == "__main__":
    main()
