"""The pipelines as library calls (agents.pipeline), and the README's Python example that uses them."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from agents.pipeline import analytic_pinches, evaluate_table, resolve_contours, run_pipeline
from warpcut.contours import builtin_names, load_contour
from warpcut.sim.config import SimConfig

SMALL = SimConfig(resolution=13)


def test_the_readme_python_example_runs(tmp_path, monkeypatch, capsys):
    """The README's first Python block (the pipelines) runs as written, in a scratch directory."""
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    block = re.search(r"## Python API.*?```python\n(.*?)```", readme, re.S).group(1)
    assert "run_pipeline(" in block and "evaluate_table(" in block
    monkeypatch.chdir(tmp_path)
    exec(compile(block, "README.md", "exec"), {})
    printed = capsys.readouterr().out
    assert "| fls-circle |" in printed and "| wave-3 |" in printed
    assert (tmp_path / "logs/example-run/results.json").is_file()
    assert (tmp_path / "logs/example-table/plans.json").is_file()


def test_run_pipeline_with_the_fixed_selector_writes_its_report(tmp_path):
    report = run_pipeline("circle-small", tmp_path, selector="fixed", candidates=3, trials=2, config=SMALL)
    assert report.methods == ["none", "fixed", "analytic"] and report.chosen_candidate == 0
    assert report.row["fixed_pinch"] == pytest.approx(report.plan.chosen["pinch"])
    assert len(report.candidates) == len(report.plan.candidates)  # fixed ranks every candidate
    written = json.loads((tmp_path / "results.json").read_text())
    assert written["policy"] == "fixed" and written["rows"][0]["contour"] == "circle-small"
    assert written["plan"]["pinch"] == pytest.approx(report.plan.chosen["pinch"])
    assert json.loads((tmp_path / "plan.json").read_text())["chosen"] == report.plan.to_json()["chosen"]
    assert report.policy_runs == []


def test_run_pipeline_with_the_analytic_selector_scores_every_candidate(tmp_path):
    report = run_pipeline("circle-small", tmp_path, selector="analytic", candidates=3, trials=2, config=SMALL)
    scores = [c["analytic_error_vertices"] for c in report.candidates]
    assert report.chosen_candidate == int(np.argmin(scores))
    assert report.row["analytic_pinch"] == pytest.approx(report.candidates[report.chosen_candidate]["pinch"])


def test_pipelines_reject_bad_settings_by_name(tmp_path):
    with pytest.raises(ValueError, match="budget: choose one of fast, paper"):
        run_pipeline("fls-circle", tmp_path, budget="huge")
    with pytest.raises(ValueError, match="selector: choose one of fixed, analytic, rl"):
        run_pipeline("fls-circle", tmp_path, selector="none")
    with pytest.raises(ValueError, match="methods: unknown magic"):
        evaluate_table(["fls-circle"], tmp_path, methods=["none", "magic"])
    with pytest.raises(ValueError, match="checkpoints: no trained run for 'fls-circle'"):
        evaluate_table(["fls-circle"], tmp_path, checkpoints=tmp_path)
    with pytest.raises(ValueError, match="analytic_pinch: choose one of feasible, centroid"):
        analytic_pinches("middle", [load_contour("fls-circle")], None)


def test_resolve_contours_expands_all_after_the_named_ones():
    named = resolve_contours(["wave-3,fls-circle", "all"])
    names = [c.name for _, c in named]
    assert names[:2] == ["wave-3", "fls-circle"] and sorted(names) == sorted(builtin_names())
    with pytest.raises(ValueError, match="contours: give at least one"):
        resolve_contours([" , "])
    with pytest.raises(ValueError, match="both named 'wave-3' .*; give it once"):
        resolve_contours("wave-3,fls-circle,wave-3")


def test_evaluate_table_without_a_plan_pairs_every_method_with_no_tension(tmp_path):
    report = evaluate_table(
        ["circle-small"], tmp_path, methods=["fixed", "analytic"], trials=2, config=SMALL, plan=False
    )
    assert report.plans is None and not (tmp_path / "plans.json").exists()
    row = report.table["rows"][0]
    assert "none_improvement_pct" not in row and row["none_error_vertices"] > 0
    assert {"fixed_improvement_pct", "analytic_improvement_pct"} <= set(report.table["mean"])
    assert (
        report.markdown().splitlines()[0] == "| contour | no tension (vertices) | fixed (%) | analytic (%) |"
    )
    assert json.loads((tmp_path / "results.json").read_text())["planned"] is False


def test_evaluate_table_trains_with_the_papers_recipe_and_records_the_kept_iteration(tmp_path):
    """--recipe paper: sparse reward, fiducials only, x-y moves, no validation: the last policy is kept."""
    from agents.config import RECIPES

    report = evaluate_table(
        "circle-small", tmp_path, methods=["fixed", "rl"], trials=2, config=SMALL, plan=False,
        recipe=RECIPES["paper"], iterations=2, num_envs=4,
    )  # fmt: skip
    options = json.loads((tmp_path / "policies/circle-small/options.json").read_text())
    assert not options["dense_reward"] and not options["contour_features"] and not options["allow_z"]
    row = report.table["rows"][0]
    assert row["rl_policy_iteration"] == 2 and report.table["rl_initial_policy_contours"] == 0
    assert np.isfinite(row["rl_improvement_pct"]) and report.policy_runs == [
        tmp_path / "policies/circle-small"
    ]


def test_evaluate_table_resumes_with_the_plans_it_saved(tmp_path, monkeypatch):
    import agents.pipeline as pipeline

    kwargs = dict(methods=["none", "fixed"], trials=1, config=SMALL, candidates=2)
    first = evaluate_table(["circle-small", "wave-1"], tmp_path, **kwargs)
    planned = []
    real = pipeline.plan_cut
    monkeypatch.setattr(pipeline, "plan_cut", lambda contour, *a, **kw: planned.append(contour.name))
    lines = []
    again = evaluate_table(["circle-small", "wave-1"], tmp_path, resume=True, log=lines.append, **kwargs)
    assert planned == [] and any("kept the 2 plan(s)" in line for line in lines)
    assert again.table["rows"] == first.table["rows"]  # the same pinch points and orders, the same cuts
    assert [p.to_json() for p in again.plans] == [p.to_json() for p in first.plans]
    saved = json.loads((tmp_path / "plans.json").read_text())
    del saved["wave-1"]  # e.g. a run that stopped while writing it (it is written whole, atomically)
    (tmp_path / "plans.json").write_text(json.dumps(saved))
    monkeypatch.setattr(
        pipeline,
        "plan_cut",
        lambda contour, *a, **kw: planned.append(contour.name) or real(contour, *a, **kw),
    )
    lines.clear()
    third = evaluate_table(["circle-small", "wave-1"], tmp_path, resume=True, log=lines.append, **kwargs)
    assert planned == ["circle-small", "wave-1"]
    assert any("planning again" in line and "no plan for 'wave-1'" in line for line in lines)
    assert third.table["rows"] == first.table["rows"]
    assert set(json.loads((tmp_path / "plans.json").read_text())) == {"circle-small", "wave-1"}


def test_evaluate_table_reports_each_stage_as_it_advances(tmp_path):
    seen = []

    def stages(stage, done, total):
        seen.append((stage, done, total))

    evaluate_table(["circle-small", "wave-1"], tmp_path, methods=["none", "fixed"], trials=1, config=SMALL,
                   candidates=2, stages=stages)  # fmt: skip
    assert [s for s in seen if s[0] == "planning"] == [
        ("planning", 0, 2),
        ("planning", 1, 2),
        ("planning", 2, 2),
    ]
    evaluating = [s for s in seen if s[0] == "evaluating"]
    assert evaluating[0][1] == 0 and evaluating[-1] == ("evaluating", 2, 2)

    seen.clear()  # without "none" listed, the suite runs it too: three batches
    evaluate_table("circle-small", tmp_path / "b", methods=["fixed", "analytic"], trials=1, config=SMALL,
                   plan=False, stages=stages)  # fmt: skip
    assert [done for stage, done, _ in seen if stage == "evaluating"] == [0, 1, 2, 3]


def test_run_trains_apg_for_its_own_iterations_unless_told():
    """The budgets' iterations are PPO's (fast: 60); an APG recipe trains APG's default (30) unless
    ``iterations`` is given."""
    from agents.config import APG_BATCH, BUDGETS, RECIPES
    from agents.pipeline import _settings

    none = {"candidates": None, "rl_candidates": None, "iterations": None, "trials": None}
    assert _settings("fast", "rl", none, RECIPES["warpcut"])["iterations"] == BUDGETS["fast"]["iterations"]
    assert _settings("fast", "rl", none, RECIPES["apg"])["iterations"] == APG_BATCH["iterations"]
    assert _settings("paper", "rl", {**none, "iterations": 5}, RECIPES["apg"])["iterations"] == 5
