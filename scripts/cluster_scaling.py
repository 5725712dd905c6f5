"""How `--ray` scales, and what the Table I suite would take on N nodes (docs/cluster.md).

Measure: the same `warpcut evaluate` (default settings, the contours given) in one process and with
`--ray local:K` for each K given, the runs alternated round by round so that a slow spell of a shared
machine falls on every variant; prints each run's wall time (the whole command: Ray's start and stop
included), its ratio to the serial run of the same round, whether its rows are the serial run's bit for bit
(but for ran_on and unit_seconds), and the units' seconds.

    python scripts/cluster_scaling.py measure --contours fls-circle,kidney,wave-1,ellipse-tilted \
        --workers 1,2 --rounds 2 --out logs/cluster-scaling

Estimate: the suite's time on N nodes of C cores, from an evaluate run's measured unit seconds (its
results.json `unit_seconds`: planning and rl per contour, on one-CPU workers with --ray, else times
--slowdown) and the Ray overheads measured below: each stage's units (plans, then policies) scheduled
longest first on N x C one-CPU workers, plus the driver's own work (the run's seconds but its planning and
rl stages, `stage_seconds`) and Ray's start.

    python scripts/cluster_scaling.py estimate RUN/results.json --start-s 8 --nodes 1,2,4,8,13,26 --cores 2

Overheads: Ray's start and stop here, a worker's first unit, and a unit's round trip.

    python scripts/cluster_scaling.py overheads
"""

from __future__ import annotations

import argparse
import heapq
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _rows(path: Path) -> list[dict]:
    from agents.cluster import same_results

    return [same_results(r) for r in json.loads(path.read_text())["rows"]]


def measure(contours: str, workers: list[int], rounds: int, out: Path, seed: int, algo: str) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    variants = [None, *workers]
    runs: list[dict] = []
    for r in range(rounds):
        for k in variants if r % 2 == 0 else reversed(variants):
            name = "serial" if k is None else f"ray-local-{k}"
            where = Path(tempfile.mkdtemp(dir=out, prefix=f"{name}-r{r}-"))
            command = [sys.executable, "-m", "warpcut", "evaluate", "--contours", contours, "--algo", algo,
                       "--seed", str(seed), "--set", "plots=false", "--out", str(where / "run")]  # fmt: skip
            if k is not None:
                command += ["--ray", f"local:{k}"]
            started = time.perf_counter()
            done = subprocess.run(command, capture_output=True, text=True)
            seconds = time.perf_counter() - started
            if done.returncode != 0:
                raise SystemExit(f"{name}: {done.stderr.strip().splitlines()[-1]}")
            (where / "log.txt").write_text(done.stdout + done.stderr)
            results = where / "run" / "results.json"
            units = [r["unit_seconds"] for r in json.loads(results.read_text())["rows"]]
            runs.append(
                {"round": r, "variant": name, "seconds": seconds, "results": str(results), "units": units}
            )
            print(f"round {r} {name}: {seconds:.0f} s", flush=True)
    report = {"contours": contours, "seed": seed, "runs": runs, "variants": {}}
    for r in range(rounds):
        serial = next(x for x in runs if x["round"] == r and x["variant"] == "serial")
        for x in runs:
            if x["round"] == r:
                x["ratio"] = x["seconds"] / serial["seconds"]
                x["same_rows"] = _rows(Path(x["results"])) == _rows(Path(serial["results"]))
    for name in dict.fromkeys(x["variant"] for x in runs):
        mine = [x for x in runs if x["variant"] == name]
        unit = {kind: [u[kind] for x in mine for u in x["units"]] for kind in ("planning", "rl")}
        report["variants"][name] = {
            "median_s": statistics.median(x["seconds"] for x in mine),
            "median_ratio": statistics.median(x["ratio"] for x in mine),
            "same_rows": all(x["same_rows"] for x in mine),
            "unit_median_s": {kind: statistics.median(v) for kind, v in unit.items()},
        }
    (out / "scaling.json").write_text(json.dumps(report, indent=2) + "\n")
    print("| variant | wall time (median s) | / serial | rows as serial | plan unit (s) | rl unit (s) |")
    print("|---|---|---|---|---|---|")
    for name, v in report["variants"].items():
        u = v["unit_median_s"]
        same = "yes" if v["same_rows"] else "NO"
        print(f"| {name} | {v['median_s']:.0f} | {v['median_ratio']:.2f} | {same} "
              f"| {u['planning']:.1f} | {u['rl']:.1f} |")  # fmt: skip
    return report


def overheads(units: int, cpus: int) -> dict:
    """Ray's own costs here: starting and stopping a local instance of ``cpus`` CPUs (the driver's kernel
    cache warm), its workers' first unit (a fresh process importing warpcut and torch), and a unit's round
    trip once they run (``units`` no-op units, median per unit)."""
    from agents.cluster import RayCluster

    started = time.perf_counter()
    cluster = RayCluster("local", cpus, "cpu", lambda _: None)
    start_s = time.perf_counter() - started
    started = time.perf_counter()
    cluster.map(_import_unit, list(range(cpus)))
    first_s = time.perf_counter() - started
    rounds = []
    for _ in range(5):
        started = time.perf_counter()
        cluster.map(abs, list(range(units)))
        rounds.append((time.perf_counter() - started) / units)
    started = time.perf_counter()
    cluster.close()
    figures = {"start_s": start_s, "first_units_s": first_s, "per_unit_s": statistics.median(rounds),
               "stop_s": time.perf_counter() - started, "cpus": cpus}  # fmt: skip
    print(json.dumps(figures, indent=2))
    return figures


def _import_unit(_: int) -> bool:
    """What a worker's first unit pays: warpcut's learners and the simulator imported."""
    import agents.training  # noqa: F401
    import warpcut.task  # noqa: F401

    return True


def makespan(seconds: list[float], workers: int) -> float:
    """The longest-first schedule of ``seconds`` on ``workers`` identical workers: its finish time."""
    loads = [0.0] * workers
    for s in sorted(seconds, reverse=True):
        heapq.heapreplace(loads, loads[0] + s)
    return max(loads)


def estimate(
    results: Path, start_s: float, per_unit_s: float, nodes: list[int], cores: int, slowdown: float
) -> None:
    report = json.loads(results.read_text())
    rows = report["rows"]
    measured = {kind: [r["unit_seconds"][kind] for r in rows if kind in r.get("unit_seconds", {})]
                for kind in ("planning", "rl")}  # fmt: skip
    units = {kind: [s * slowdown for s in v] for kind, v in measured.items()}
    stages = report["stage_seconds"]  # the driver's own work: all but the planning and rl stages
    driver = report["seconds"] - stages.get("planning", 0.0) - stages.get("rl", 0.0)
    print(f"{len(rows)} contours; unit seconds x {slowdown:g} (one-CPU workers): planning "
          f"{sum(units['planning']):.0f} s in all (longest {max(units['planning'], default=0):.0f}), rl "
          f"{sum(units['rl']):.0f} s (longest {max(units['rl'], default=0):.0f}); the driver's own work "
          f"{max(driver, 0):.0f} s")  # fmt: skip
    print("| nodes | workers | estimate (min) |")
    print("|---|---|---|")
    for n in nodes:
        w = n * cores
        total = start_s + max(driver, 0.0)
        for kind in ("planning", "rl"):
            total += makespan(units[kind], w) + per_unit_s * len(units[kind]) / w
        print(f"| {n} | {w} | {total / 60:.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    m = sub.add_parser("measure")
    m.add_argument("--contours", default="fls-circle,kidney,wave-1,ellipse-tilted")
    m.add_argument("--workers", default="1,2")
    m.add_argument("--rounds", type=int, default=2)
    m.add_argument("--seed", type=int, default=0)
    m.add_argument("--algo", default="gps", help="the rl column's learner (docs/cluster.md measured es)")
    m.add_argument("--out", type=Path, default=Path("logs/cluster-scaling"))
    o = sub.add_parser("overheads")
    o.add_argument("--units", type=int, default=200)
    o.add_argument("--cpus", type=int, default=2)
    e = sub.add_parser("estimate")
    e.add_argument("results", type=Path)
    e.add_argument("--start-s", type=float, required=True, help="Ray's start and stop, measured (s)")
    e.add_argument("--per-unit-s", type=float, default=0.05, help="Ray's overhead per unit (s)")
    e.add_argument("--nodes", default="1,2,4,8,13,26")
    e.add_argument("--cores", type=int, default=2)
    e.add_argument("--slowdown", type=float, default=1.0,
                   help="a unit's seconds on a one-CPU worker over those in the results")  # fmt: skip
    args = parser.parse_args()
    if args.what == "measure":
        workers = [int(k) for k in args.workers.split(",")]
        measure(args.contours, workers, args.rounds, args.out, args.seed, args.algo)
    elif args.what == "overheads":
        overheads(args.units, args.cpus)
    else:
        estimate(args.results, args.start_s, args.per_unit_s, [int(n) for n in args.nodes.split(",")],
                 args.cores, args.slowdown)  # fmt: skip


if __name__ == "__main__":
    main()
