"""Which gains on its moves the generalist should choose among, and at how many of its best candidates
(why :data:`agents.config.GENERALIST_GAINS` and :data:`agents.config.GAIN_SHORTLIST` are what they are).

For each contour, planned as ``evaluate`` plans it (its 30 pinch candidates, each in its best order): the
shipped generalist's errors at every candidate and gain, on the validation episodes ``guarded_result`` reads
(seeded ``VALIDATION_SEED_OFFSET`` apart) and on the evaluation's trials, and holding still's and no
tension's on both. Then each way of choosing (a set of gains, tried at the best N candidates by the
validation with the moves as they are) is scored as the guard before the fresh episodes' check played it:
the option with the lowest validation error, or holding still where that is no lower than holding still's,
and the evaluation trials of what it chose (improvement over no tension from the mean errors, averaged over
contours). Run it on the ``validation`` stream, never on the test contours or the suite.

Run: python experiments/generalist_gains.py --contours gen-validation-0:48 --out gains.jsonl
[--gains 0.5,0.75,1,1.25,1.5]; with --read gains.jsonl, only the table.
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

import numpy as np


def _measure(args) -> None:
    from agents.config import EVALUATION_CANDIDATES
    from agents.evaluation import run_method
    from agents.generalist import VALIDATION_EPISODES, generalist_result, load_generalist
    from agents.policies import VALIDATION_SEED_OFFSET
    from warpcut.planning import plan_cut, resolve_specs
    from warpcut.sim.config import SimConfig

    config, generalist = SimConfig(), load_generalist(args.generalist)
    gains = [float(g) for g in args.gains.split(",")]
    with open(args.out, "w") as out:
        for name, contour in resolve_specs(args.contours.split(","), config):
            plan = plan_cut(
                contour, config.replace(noise_std=0.0), num_candidates=EVALUATION_CANDIDATES, seed=0
            )
            listed = plan.ranked()
            pinches = [np.asarray(c["pinch"]) for c in listed]
            cuts = [plan.ordered_segments(c["order"]) for c in listed]
            row = {"contour": name, "gains": gains}
            for label, seed, n in (
                ("val", VALIDATION_SEED_OFFSET, VALIDATION_EPISODES),
                ("test", 0, args.trials),
            ):
                k = len(listed)
                for g in gains:
                    errors = generalist_result(
                        generalist, [contour] * k, pinches, cuts, n, config, None, seed, gains=[g] * k
                    ).error_vertices
                    row[f"{label}_{g:g}"] = errors.mean(axis=1).tolist()
                for what, pinch in (("still", pinches[0]), ("none", None)):
                    errors = run_method([contour], [pinch], None, n, config, None, seed, segments=[cuts[0]])
                    row[f"{label}_{what}"] = float(errors.error_vertices.mean())
            out.write(json.dumps(row) + "\n")
            print(name, flush=True)


def _chosen(row: dict, gains: list[float], shortlist: int) -> float:
    """The evaluation's mean error of what the guard (before its fresh episodes) chooses."""
    ones = np.asarray(row["val_1"])
    top = np.argsort(ones, kind="stable")[:shortlist]
    options = [(ones[k], 1.0, k) for k in range(len(ones))]
    options += [(row[f"val_{g:g}"][k], g, int(k)) for g in gains if g != 1.0 for k in top]
    error, gain, k = min(options, key=lambda o: o[0])
    return row["test_still"] if error >= row["val_still"] else row[f"test_{gain:g}"][k]


def _table(path: Path) -> None:
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    measured = [g for g in rows[0]["gains"] if g != 1.0]

    def score(gains, shortlist) -> float:
        return float(np.mean([100 * (1 - _chosen(r, gains, shortlist) / r["test_none"]) for r in rows]))

    still = np.mean([100 * (1 - r["test_still"] / r["test_none"]) for r in rows])
    print(f"{len(rows)} contours; holding still at the planned pinch point: {still:+.1f}%")
    print("| gains besides 1 | best 3 | best 5 | best 8 | all |")
    print("|---|---|---|---|---|")
    sets = [()] + [s for size in (1, 2, len(measured)) for s in itertools.combinations(measured, size)]
    for gains in dict.fromkeys(sets):
        cells = [f"{score([1.0, *gains], n):+.1f}" for n in (3, 5, 8, 10**6)]
        print(f"| {', '.join(f'{g:g}' for g in gains) or 'none'} | " + " | ".join(cells) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--contours", default="gen-validation-0:48")
    parser.add_argument("--gains", default="0.5,0.75,1,1.25,1.5", help="1 among them")
    parser.add_argument("--generalist", default="generalist")
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("logs/generalist-gains.jsonl"))
    parser.add_argument("--read", type=Path, help="a finished --out file: print its table only")
    args = parser.parse_args()
    if args.read is None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        _measure(args)
    _table(args.read or args.out)


if __name__ == "__main__":
    main()
