"""Learners and their settings side by side under the Table I protocol, on the same plans: why the default
learner and each learner's defaults are what they are (es against PPO and APG, PPO's entropy bonus, its
"stay" prior, its passes per update, dense against sparse reward, model selection's margin, the paper's
preset).

Each contour is planned once (noise-free; kept in OUT/plans.json and reused by later runs into OUT); then,
for each variant, a policy is trained per contour at the planned pinch and order and evaluated against
none / fixed / analytic over paired, noisy trials (:func:`agents.pipelines.evaluate_table` with the plans),
into OUT/VARIANT (a finished variant is read back, an interrupted one continues). Prints per variant the
suite means, rl's lead over the better baseline, on how many contours rl is best or within its CI of the
best, on how many model selection kept the initial policy, and the training time per contour.

Run: python experiments/learner_settings.py --out DIR [--variants es,ppo,...] [--variant NAME:KEY=VALUE;...]
     [--contours fls-circle,kidney,crescent,arc-top,s-curve,e-shape] [--iterations N] [--trials 10]
     [--set KEY=VALUE ...]
A variant is a set of ``warpcut evaluate`` keys (``--print-config``) on top of the defaults; ``--list``
shows the built-in ones. ``--set`` applies to every variant (e.g. --set train.num_envs=64); the plans'
settings (sim.*, candidates, arm.*, seed) are common to all variants.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from agents.config_io import apply, flatten, parse_override, read_file
from agents.jobs import EvaluateJob, with_dependent_defaults
from agents.pipelines import evaluate_table
from warpcut.io import read_json, write_json
from warpcut.planning import Plan, plan_cut, resolve_specs

PPO = {"train.algo": "ppo"}
VARIANTS: dict[str, dict] = {
    "gps": {"train.algo": "gps"},
    "es": {"train.algo": "es"},
    "es-no-feedback": {
        "train.algo": "es",
        "train.es.feedback": False,
        "train.es.sigma": 0.05,
        "train.es.learning_rate": 0.01,
    },
    "ppo": PPO,
    "ppo-entropy-0.01": {**PPO, "train.ppo.entropy_coef": 0.01},
    "ppo-entropy-0.1": {**PPO, "train.ppo.entropy_coef": 0.1},
    "ppo-no-prior": {**PPO, "train.ppo.stay_prior": 0.0},
    "ppo-5-epochs": {**PPO, "train.ppo.num_learning_epochs": 5},
    "ppo-sparse": {**PPO, "env.dense_reward": False},
    "ppo-continuous": {**PPO, "env.action_type": "continuous"},
    "ppo-margin-0": {**PPO, "train.selection_margin": 0.0},
    "apg": {"train.algo": "apg"},
    "paper": flatten(read_file("paper")),
}
"""The built-in variants: the default learner (gps), es, es without its feedback path (with the step sizes its
docstring names), PPO with its defaults and with one changed, APG, and the paper's preset."""

PLAN_KEYS = ("sim.", "candidates", "arm.", "seed", "contours")
"""Keys a variant may not change: the plans (and the protocol) are common to every variant."""


def parse_variant(text: str) -> tuple[str, dict]:
    """``NAME:KEY=VALUE;KEY=VALUE`` as ``(name, {key: value})``."""
    name, sep, body = text.partition(":")
    if not sep or not name:
        raise SystemExit(f"--variant: {text!r}: give NAME:KEY=VALUE;KEY=VALUE")
    return name, dict(parse_override(item) for item in body.split(";") if item.strip())


def variant_job(base: EvaluateJob, common: dict, changes: dict, name: str) -> EvaluateJob:
    """``base`` with the variant's ``changes``, then the ``--set`` ones; checked before any work."""
    for key in changes:
        if key.startswith(PLAN_KEYS):
            raise SystemExit(f"variant {name}: {key}: the plans' settings are common; give it with --set")
    given = {**changes, **common}
    try:
        job = with_dependent_defaults(apply(base, given, f"variant {name}"), set(given)).check()
        job.train.check(job.env.action_type == "discrete")
    except ValueError as error:
        raise SystemExit(f"variant {name}: {error}") from None
    return job


def suite_plans(job: EvaluateJob, out: Path) -> list[Plan]:
    """The plans of ``job``'s contours as ``warpcut evaluate`` makes them, made once into
    ``out/plans.json``."""
    contours = [c for _, c in resolve_specs(job.contours)]
    config = job.sim.validated().replace(noise_std=0.0)
    path = out / "plans.json"
    saved = read_json(path) if path.is_file() else {}
    plans = []
    for contour in contours:
        if contour.name in saved:
            plans.append(Plan.from_json(saved[contour.name], contour, config))
            continue
        plan = plan_cut(contour, config, num_candidates=job.candidates, seed=job.seed, arm=job.arm)
        plans.append(plan)
        saved[contour.name] = plan.to_json()
        write_json(path, saved)
    return plans


def summarise(rows: list[dict]) -> dict:
    """Suite means and rl's standing among the methods (best, or within its CI of the best)."""
    means = {
        m: float(np.mean([r[f"{m}_improvement_pct"] for r in rows])) for m in ("fixed", "analytic", "rl")
    }
    within = 0
    for r in rows:
        best = max(r[f"{m}_improvement_pct"] for m in ("fixed", "analytic", "rl"))
        within += r["rl_improvement_pct"] + r["rl_ci95"] >= best
    kept = [r.get("rl_policy_iteration") for r in rows]
    return {
        **{f"{m}_mean_pct": v for m, v in means.items()},
        "rl_lead_pct": means["rl"] - max(means["fixed"], means["analytic"]),
        "rl_best_or_within_ci": within,
        "rl_initial_policy": sum(1 for k in kept if k == 0),
        "contours": len(rows),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, help="the plans, a run directory per variant, results.json")
    parser.add_argument("--variants", default="es,ppo", help="built-in variants, comma-separated (--list)")
    parser.add_argument("--variant", action="append", default=[], metavar="NAME:KEY=VALUE;...")
    parser.add_argument("--contours", default="fls-circle,kidney,crescent,arc-top,s-curve,e-shape")
    parser.add_argument("--iterations", type=int, default=None, help="per policy (default: each learner's)")
    parser.add_argument("--trials", type=int, default=None, help="evaluation trials (default: evaluate's)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--list", action="store_true", help="print the built-in variants and exit")
    args = parser.parse_args()
    if args.list:
        for name, changes in VARIANTS.items():
            print(f"{name}: " + (", ".join(f"{k}={v}" for k, v in changes.items()) or "the defaults"))
        return
    if args.out is None:
        parser.error("--out: give the directory for the plans and the runs")
    common = dict(parse_override(text) for text in args.overrides)
    if args.iterations is not None:
        common["train.iterations"] = args.iterations
    if args.trials is not None:
        common["trials"] = args.trials
    base = EvaluateJob(
        contours=args.contours.split(","), methods=["none", "fixed", "analytic", "rl"], plots=False
    )
    chosen = {}
    for name in [v.strip() for v in args.variants.split(",") if v.strip()]:
        if name not in VARIANTS:
            parser.error(f"--variants: {name}: not built in; choose from {', '.join(VARIANTS)}")
        chosen[name] = VARIANTS[name]
    chosen |= dict(parse_variant(text) for text in args.variant)
    jobs = {name: variant_job(base, common, changes, name) for name, changes in chosen.items()}
    plan_job = variant_job(base, common, {}, "plans")
    torch.set_num_threads(1)
    start = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    plans = suite_plans(plan_job, args.out)
    print(f"planned {len(plans)} contours in {time.perf_counter() - start:.0f} s", flush=True)
    results = {}
    for name, job in jobs.items():
        out = args.out / name
        start = time.perf_counter()
        resume = (out / "config.json").is_file()
        report = evaluate_table(job, out, plans=plans, resume=resume)
        train_s = [
            json.loads((run / "summary.json").read_text())["wall_time_s"] for run in report.policy_runs
        ]
        summary = {
            **summarise(report.table["rows"]),
            "train_s_per_contour": float(np.mean(train_s)) if train_s else None,
            "seconds": time.perf_counter() - start,
        }
        results[name] = {
            "changes": {**chosen[name], **common},
            "summary": summary,
            "rows": report.table["rows"],
        }
        trained = "-" if summary["train_s_per_contour"] is None else f"{summary['train_s_per_contour']:.0f}"
        print(
            f"{name:<16} fixed {summary['fixed_mean_pct']:+6.1f}  "
            f"analytic {summary['analytic_mean_pct']:+6.1f}  rl {summary['rl_mean_pct']:+6.1f}  "
            f"lead {summary['rl_lead_pct']:+5.1f}  best/within {summary['rl_best_or_within_ci']}/"
            f"{summary['contours']}  initial kept {summary['rl_initial_policy']}  train {trained} s/contour",
            flush=True,
        )
        write_json(args.out / "results.json", {"args": {k: str(v) for k, v in vars(args).items()}, **results})


if __name__ == "__main__":
    main()
