"""The pipelines as library calls (agents.pipelines), each taking its job (agents.jobs), and the README's
Python example that uses them."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from agents.cluster import same_results
from agents.config import BUDGETS
from agents.config_io import apply, read_file, to_plain
from agents.jobs import EvaluateJob, RunJob, with_dependent_defaults
from agents.pipelines import evaluate_table, run_pipeline
from agents.pipelines.common import analytic_pinches
from warpcut.contours import builtin_names, load_contour
from warpcut.planning import resolve_specs
from warpcut.sim.config import SimConfig

SMALL = SimConfig(resolution=13)


def test_the_readme_python_examples_run(tmp_path, monkeypatch, capsys):
    """The README's Python blocks of the env and of the pipelines run as written, in a scratch directory."""
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", readme, re.S)
    gym_block = next(b for b in blocks if "gym.make(" in b)
    pipelines = next(b for b in blocks if "run_pipeline(" in b and "evaluate_table(" in b)
    assert "from agents.pipelines import" in pipelines and "agents.pipeline " not in pipelines
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(gym_block, "README.md", "exec"), scope)
    assert scope["env"].observation_space.shape == (47,) and scope["env"].action_space.shape == (3,)
    exec(compile(pipelines, "README.md", "exec"), {})
    printed = capsys.readouterr().out
    assert "| **mean** |" in printed
    runs = {p.parent for p in tmp_path.rglob("results.json")}
    assert len(runs) == 2 and all((run / "config.json").is_file() for run in runs)


def test_run_pipeline_with_the_fixed_selector_writes_its_report_and_its_job(tmp_path):
    job = RunJob(contour="circle-small", policy="fixed", candidates=3, trials=2, sim=SMALL)
    report = run_pipeline(job, tmp_path)
    assert report.methods == ["none", "fixed", "analytic"] and report.chosen_candidate == 0
    assert report.row["fixed_pinch"] == pytest.approx(report.plan.chosen["pinch"])
    assert len(report.candidates) == len(report.plan.candidates)  # fixed ranks every candidate
    written = json.loads((tmp_path / "results.json").read_text())
    assert written["policy"] == "fixed" and written["rows"][0]["contour"] == "circle-small"
    assert written["plan"]["pinch"] == pytest.approx(report.plan.chosen["pinch"])
    assert json.loads((tmp_path / "plan.json").read_text())["chosen"] == report.plan.to_json()["chosen"]
    assert report.policy_runs == [] and not (tmp_path / "request.json").exists()
    saved = json.loads((tmp_path / "config.json").read_text())
    assert saved == to_plain(job) == to_plain(apply(RunJob(), saved, "config.json"))  # the job, read back


def test_run_pipeline_with_the_analytic_selector_scores_every_candidate(tmp_path):
    job = RunJob(contour="circle-small", policy="analytic", candidates=3, trials=2, sim=SMALL)
    report = run_pipeline(job, tmp_path)
    scores = [c["analytic_error_vertices"] for c in report.candidates]
    assert report.chosen_candidate == int(np.argmin(scores))
    assert report.row["analytic_pinch"] == pytest.approx(report.candidates[report.chosen_candidate]["pinch"])


def test_pipelines_reject_bad_settings_by_name(tmp_path):
    with pytest.raises(ValueError, match="budget: choose one of fast, paper"):
        run_pipeline(RunJob(budget="huge"), tmp_path)
    with pytest.raises(ValueError, match="policy: choose one of fixed, analytic, rl"):
        run_pipeline(RunJob(policy="none"), tmp_path)
    with pytest.raises(ValueError, match="candidates: must be an integer >= 1"):
        run_pipeline(RunJob(candidates=0), tmp_path)
    physics = SimConfig()
    physics.chebyshev_rho = 0.99  # each field alone is fine; with 7 sweeps it is not
    with pytest.raises(ValueError, match="^sim.chebyshev_rho: "):  # by the job's key, before any work
        run_pipeline(RunJob(policy="fixed", sim=physics), tmp_path / "bad-sim")
    assert not (tmp_path / "bad-sim").exists()
    with pytest.raises(ValueError, match="methods: unknown magic"):
        evaluate_table(EvaluateJob(contours=["fls-circle"], methods=["none", "magic"]), tmp_path)
    with pytest.raises(ValueError, match="checkpoints: no trained run for 'fls-circle'"):
        evaluate_table(EvaluateJob(contours=["fls-circle"], checkpoints=str(tmp_path)), tmp_path)
    with pytest.raises(ValueError, match="analytic_pinch: choose one of feasible, centroid"):
        analytic_pinches("middle", [load_contour("fls-circle")], None)
    assert not (tmp_path / "config.json").exists()  # refused before anything was written


def test_the_budgets_leave_the_iterations_to_the_learner():
    """A budget sets the candidates and trials (the generalist's plan, which trains nothing, has the paper's
    30 candidates with either); each policy trains for its learner's own iterations unless
    ``train.iterations`` is given."""
    assert RunJob().settings() == {"candidates": 8, "rl_candidates": 1, "trials": 10}
    paper = {"candidates": 30, "rl_candidates": None, "trials": 3}
    assert RunJob(budget="paper", trials=3).settings() == paper
    assert RunJob(policy="generalist").settings()["candidates"] == 30
    assert RunJob(policy="generalist", candidates=5).settings()["candidates"] == 5
    assert RunJob(policy="fixed").settings()["candidates"] == BUDGETS["fast"]["candidates"] == 8
    assert all("iterations" not in budget for budget in BUDGETS.values())
    assert RunJob().train.iterations is None


def test_resolve_specs_expands_all_after_the_named_ones():
    named = resolve_specs(["wave-3,fls-circle", "all"])
    names = [c.name for _, c in named]
    assert names[:2] == ["wave-3", "fls-circle"] and sorted(names) == sorted(builtin_names())
    with pytest.raises(ValueError, match="contours: give at least one"):
        resolve_specs([" , "])
    with pytest.raises(ValueError, match="both named 'wave-3' .*; give it once"):
        resolve_specs("wave-3,fls-circle,wave-3")


def test_evaluate_table_without_a_plan_pairs_every_method_with_no_tension(tmp_path):
    job = EvaluateJob(
        contours=["circle-small"], methods=["fixed", "analytic"], trials=2, sim=SMALL, plan=False
    )
    report = evaluate_table(job, tmp_path)
    assert report.plans is None and not (tmp_path / "plans.json").exists()
    row = report.table["rows"][0]
    assert "none_improvement_pct" not in row and row["none_error_vertices"] > 0
    assert {"fixed_improvement_pct", "analytic_improvement_pct"} <= set(report.table["mean"])
    assert (
        report.markdown().splitlines()[0] == "| contour | no tension (vertices) | fixed (%) | analytic (%) |"
    )
    assert json.loads((tmp_path / "results.json").read_text())["planned"] is False
    assert (tmp_path / "results.md").read_text() == report.markdown() + "\n"  # always written
    assert json.loads((tmp_path / "config.json").read_text()) == to_plain(job)


def test_evaluate_table_trains_with_the_papers_learner_and_records_the_kept_iteration(tmp_path):
    """``--config paper``: PPO, sparse reward, fiducials only, x-y moves, no validation: the last policy is
    kept."""
    job = EvaluateJob(contours=["circle-small"], methods=["fixed", "rl"], trials=2, sim=SMALL, plan=False)
    job = apply(job, read_file("paper"), "paper")
    job = apply(job, {"train.iterations": 2, "train.num_envs": 4}, "--set")
    assert job.train.algo == "ppo" and job.env.action_type == "discrete"
    report = evaluate_table(job, tmp_path)
    options = json.loads((tmp_path / "policies/circle-small/options.json").read_text())
    assert not options["dense_reward"] and not options["contour_features"] and not options["allow_z"]
    assert options["action_type"] == "discrete"
    row = report.table["rows"][0]
    assert row["rl_policy_iteration"] == 2 and report.table["rl_initial_policy_contours"] == 0
    assert np.isfinite(row["rl_improvement_pct"]) and report.policy_runs == [
        tmp_path / "policies/circle-small"
    ]
    trained = json.loads((tmp_path / "policies/circle-small/config.json").read_text())
    assert trained["train"]["algo"] == "ppo" and trained["train"]["validation_trials"] == 0


def test_the_papers_preset_names_only_settings_the_jobs_have():
    """The preset reads into every job that trains, and ``ppo`` keeps its discrete moves as a default
    that follows it."""
    for job_class in (RunJob, EvaluateJob):
        job = with_dependent_defaults(apply(job_class(), read_file("paper"), "paper"), set())
        assert job.train.algo == "ppo" and job.env.action_type == "discrete" and not job.env.allow_z


def test_evaluate_table_resumes_with_the_plans_it_saved(tmp_path, monkeypatch):
    import agents.pipelines.table as table

    job = EvaluateJob(
        contours=["circle-small", "wave-1"], methods=["none", "fixed"], trials=1, sim=SMALL, candidates=2
    )
    first = evaluate_table(job, tmp_path)
    planned = []
    real = table.plan_cut
    monkeypatch.setattr(table, "plan_cut", lambda contour, *a, **kw: planned.append(contour.name))
    lines = []
    again = evaluate_table(job, tmp_path, resume=True, log=lines.append)
    assert planned == [] and any("kept the 2 plan(s)" in line for line in lines)
    # the same pinch points and orders, the same cuts
    assert [same_results(r) for r in again.table["rows"]] == [same_results(r) for r in first.table["rows"]]
    assert [p.to_json() for p in again.plans] == [p.to_json() for p in first.plans]
    saved = json.loads((tmp_path / "plans.json").read_text())
    del saved["wave-1"]  # e.g. a run that stopped while writing it (it is written whole, atomically)
    (tmp_path / "plans.json").write_text(json.dumps(saved))
    monkeypatch.setattr(
        table,
        "plan_cut",
        lambda contour, *a, **kw: planned.append(contour.name) or real(contour, *a, **kw),
    )
    lines.clear()
    third = evaluate_table(job, tmp_path, resume=True, log=lines.append)
    assert planned == ["circle-small", "wave-1"]
    assert any("planning again" in line and "no plan for 'wave-1'" in line for line in lines)
    assert [same_results(r) for r in third.table["rows"]] == [same_results(r) for r in first.table["rows"]]
    assert set(json.loads((tmp_path / "plans.json").read_text())) == {"circle-small", "wave-1"}


def test_evaluate_table_reports_each_stage_as_it_advances(tmp_path):
    seen = []

    def stages(stage, done, total):
        seen.append((stage, done, total))

    job = EvaluateJob(
        contours=["circle-small", "wave-1"], methods=["none", "fixed"], trials=1, sim=SMALL, candidates=2
    )
    evaluate_table(job, tmp_path, stages=stages)
    assert [s for s in seen if s[0] == "planning"] == [
        ("planning", 0, 2),
        ("planning", 1, 2),
        ("planning", 2, 2),
    ]
    evaluating = [s for s in seen if s[0] == "evaluating"]
    assert evaluating[0][1] == 0 and evaluating[-1] == ("evaluating", 2, 2)

    seen.clear()  # without "none" listed, the suite runs it too: three batches
    job = EvaluateJob(
        contours=["circle-small"], methods=["fixed", "analytic"], trials=1, sim=SMALL, plan=False
    )
    evaluate_table(job, tmp_path / "b", stages=stages)
    assert [done for stage, done, _ in seen if stage == "evaluating"] == [0, 1, 2, 3]


@pytest.mark.parametrize(
    ("methods", "trials"), [(["none"], 2), (["none", "fixed"], 1), (["none", "fixed"], 2)]
)
def test_the_markdown_table_is_well_formed_and_shows_a_ci_only_over_two_or_more_values(
    tmp_path, methods, trials
):
    """Every line has the header's columns (with none alone too); a per-contour cell has a CI only over two
    or more trials, and the mean of one contour has none (a CI of one sample does not exist)."""
    job = EvaluateJob(contours=["circle-small"], methods=methods, trials=trials, candidates=2, sim=SMALL)
    table = evaluate_table(job, tmp_path / "t").markdown()
    lines = table.splitlines()
    assert len({line.count("|") for line in lines}) == 1, table
    assert lines[1] == "|" + "---|" * (2 + len(methods) - 1)
    body, mean = lines[2], lines[-1]
    assert ("±" in body) == (trials >= 2 and "fixed" in methods) and "±" not in mean, table
    assert (tmp_path / "t" / "results.md").read_text().strip().endswith(mean)
