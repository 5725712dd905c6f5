"""How fast per-contour training reaches its own level when it starts from the generalist
(``warpcut train --set init=generalist``) instead of from "hold still": docs/results.md, "Fine-tuning".

For each contour: the contour planned as ``warpcut evaluate`` plans it (its pinch point, segments and
order), then es trained for it twice with the same seed, iterations and validation episodes: from scratch
(the default env and policy) and from the generalist (its look-ahead env and network). The scratch run's
kept validation error is "the per-contour level"; the table gives the training iterations each run needed to
first validate at or below it (the generalist's zero-shot error counts, at 0), and their ratio. ``--at
generalist``: both train at the plan's candidate (pinch point and order) where the generalist validates
best, as ``evaluate`` and ``run`` play it and ``train`` fine-tunes it by default
(:func:`agents.generalist.generalist_cut`), instead of at the planned pinch point.

``--init-gain G``: the factor on the generalist's moves fine-tuning starts from (default: ``train``'s,
:data:`agents.config.FINE_TUNING_GAIN`).

Run: python scripts/fine_tuning.py --contours fls-circle,kidney,gen-test-0:2 [--at plan|generalist]
[--generalist DIR] [--init-gain G] [--out DIR]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np


def _plan(contour, config, seed):
    from agents.config import EVALUATION_CANDIDATES
    from warpcut.planning import plan_cut

    return plan_cut(contour, config.replace(noise_std=0.0), num_candidates=EVALUATION_CANDIDATES, seed=seed)


def _curve(summary: dict) -> list[tuple[int, float]]:
    """``(iterations trained, validation error)`` of each validation of a run, from its summary: iterations,
    not seconds, so that runs made at different times on a shared machine compare (an iteration of either
    run is the same batch of whole cuts; the look-ahead observation costs a little more a step)."""
    return [(v["iterations"], v["error"]) for v in summary["validation"]]


def _reached(curve: list[tuple[float, float]], level: float) -> float | None:
    return next((t for t, error in curve if error <= level), None)


def main() -> None:
    from agents.config import TrainConfig
    from agents.generalist import generalist_cut, load_generalist
    from agents.jobs import TrainJob
    from agents.training import train_contour
    from warpcut.planning import resolve_contour, resolve_specs
    from warpcut.sim.config import SimConfig

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--contours", default="fls-circle,kidney,gen-test-0:2")
    parser.add_argument("--generalist", default="generalist")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--at", choices=("plan", "generalist"), default="plan", help="where both runs pinch")
    parser.add_argument(
        "--init-gain", type=float, default=None, help="the factor on the generalist's moves it starts from"
    )
    parser.add_argument("--out", type=Path, default=Path("logs/fine-tuning"))
    args = parser.parse_args()
    config = SimConfig()
    rows = []
    for name, contour in resolve_specs(args.contours.split(","), config):
        if args.at == "generalist":  # where the generalist plays, as train's fine-tuning starts by default
            pinch, segments = generalist_cut(
                load_generalist(args.generalist), contour, config, seed=args.seed
            )
        else:  # the planned pinch point and order
            plan = _plan(contour, config, args.seed)
            pinch, segments = plan.chosen["pinch"], plan.ordered_segments()
        base = TrainJob(
            contour=name,
            pinch=[float(v) for v in pinch],
            segments=[np.asarray(s).tolist() for s in segments],
            seed=args.seed,
            train=TrainConfig(algo="es"),  # fine-tuning is es's: the scratch run is es's too
            plots=False,
        )
        resolve_contour(base.contour, base.sim)  # a bad name: now
        runs = {}
        tuned = _fine_tuning(base, args.generalist, args.init_gain)
        for label, job in (("scratch", base), ("generalist", tuned)):
            out = args.out / name / label
            if not (out / "summary.json").is_file():
                train_contour(job, out, progress=False)
            runs[label] = json.loads((out / "summary.json").read_text())
        scratch, tuned = _curve(runs["scratch"]), _curve(runs["generalist"])
        level = runs["scratch"]["best"]["validation_error"]
        rows.append(
            {
                "contour": name,
                "level": level,
                "zero_shot": tuned[0][1],
                "scratch_s": _reached(scratch, level),
                "generalist_s": _reached(tuned, level),
                "generalist_best": runs["generalist"]["best"]["validation_error"],
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    print("| contour | per-contour level (vertices) | generalist zero-shot | scratch reaches it (iterations) "
          "| from the generalist | ratio | fine-tuned best |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        ratio = (
            "n/a"
            if r["generalist_s"] is None or not r["scratch_s"]
            else f"{r['generalist_s'] / r['scratch_s']:.2f}"
        )
        reached = "not reached" if r["generalist_s"] is None else f"{r['generalist_s']}"
        print(
            f"| {r['contour']} | {r['level']:.1f} | {r['zero_shot']:.1f} | {r['scratch_s']} | "
            f"{reached} | "
            f"{ratio} | {r['generalist_best']:.1f} |"
        )
    ratios = [
        r["generalist_s"] / r["scratch_s"] for r in rows if r["generalist_s"] is not None and r["scratch_s"]
    ]
    if ratios:
        print(
            f"median ratio of iterations: {np.median(ratios):.2f} over {len(ratios)} of {len(rows)} contours"
        )


def _fine_tuning(base, generalist: str, gain: float | None):
    """``base`` started from the generalist, observing and acting as it does, its moves scaled by ``gain``
    (None: the job's default, :data:`agents.config.FINE_TUNING_GAIN`)."""
    from agents.jobs import with_dependent_defaults

    job = dataclasses.replace(base, init=generalist)
    if gain is not None:
        job = dataclasses.replace(job, init_gain=gain)
    return with_dependent_defaults(job, set())


if __name__ == "__main__":
    main()
