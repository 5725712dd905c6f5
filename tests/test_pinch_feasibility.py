"""Pinch feasibility wherever a pinch point is given: one the gripper could not hold (on the cut line, under
the cutting arm) is refused in one line naming the rule it breaks, runs only behind
``allow_infeasible_pinch``, and every output of such a run says so; the default pinch points are feasible
by construction."""

import json

import gymnasium as gym
import numpy as np
import pytest
from cli_runner import invoke, refused

from agents.evaluation import Method, compare_policies, evaluate_suite
from agents.jobs import OptimizeJob
from agents.pipelines import optimize_contour
from envs import ENV_ID
from envs.options import PatternCutOptions
from warpcut.contours import load_contour
from warpcut.planning import ArmModel, InfeasiblePinch, default_pinch, pinch_candidates, pinch_problems
from warpcut.sim.config import SimConfig
from warpcut.sim.simulator import Simulator
from warpcut.task import CuttingTask

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SMALL = SimConfig(resolution=13)
FLS = load_contour("fls-circle")
ON_CUT = [25.0, 50.0]
"""fls-circle's leftmost point: on the cut line (and under the arm, which passes over every point cut)."""
CENTROID = [50.0, 50.0]
"""fls-circle's centroid: clear of the cut line, under the cutting arm (it sweeps the piece being cut)."""
FEASIBLE = [83.0, 83.0]
"""fls-circle's default pinch point on the 13 x 13 sheet."""
SHEET = ["--set", "sim.resolution=13"]
ALLOW = ["--set", "allow_infeasible_pinch=true"]
TINY_TRAINING = [
    *(
        "--num-envs",
        "8",
        "--set",
        "train.algo=es",
        "--set",
        "train.es.population=4",
        "--iterations",
        "1",
        "--set",
        "eval_trials=1",
    ),
    *("--set", "train.validation_trials=0", "--set", "plots=false", "--no-progress"),
]


def assert_names_the_rule(message: str, rule: str) -> None:
    """``message`` refuses a pinch point for breaking ``rule`` and says how to fix or allow it."""
    assert "is not a feasible grasp for fls-circle" in message and rule in message, message
    assert "omit it (--pinch)" in message and "--set allow_infeasible_pinch=true" in message, message


def test_pinch_problems_name_each_rule_a_point_breaks():
    cut, centroid, feasible, edge, off = pinch_problems(
        [ON_CUT, CENTROID, FEASIBLE, [3.0, 50.0], [120.0, 50.0]], FLS, SMALL
    )
    assert cut.startswith("on the cut line (0.0 mm from the contour") and "under the cutting arm" in cut
    assert centroid.startswith("under the cutting arm") and "cut line" not in centroid
    assert feasible is None
    assert edge.startswith("closer to the sheet's edge than the grasp radius")
    assert "off the 100 x 100 mm sheet" in off
    assert pinch_problems([50.0, 85.0], FLS, SMALL)[0].startswith("too near the cut line (10.0 mm")
    # An arm that collides only near its tip leaves the piece's middle free.
    assert pinch_problems(CENTROID, FLS, SMALL, arm=ArmModel(length_mm=5.0)) == [None]


@pytest.mark.parametrize(
    ("name", "resolution"),
    [("fls-circle", 13), ("fls-circle", 25), ("crescent", 25), ("edge-bite", 25), ("wave-1", 25)],
)
def test_default_pinch_points_and_the_planners_candidates_are_feasible(name, resolution):
    """Where the centroid is under the arm (fls-circle, edge-bite), on the cut line (crescent) or feasible
    (wave-1), the default pinch point and the planner's candidates are feasible by construction."""
    contour, config = load_contour(name), SimConfig(resolution=resolution)
    assert pinch_problems(default_pinch(contour, config), contour, config) == [None]
    candidates = pinch_candidates(contour, config, num=4, rng=np.random.default_rng(0))
    assert pinch_problems(candidates, contour, config) == [None] * len(candidates)


def test_cutting_task_refuses_an_infeasible_pinch_unless_allowed():
    for point, rule in ((ON_CUT, "on the cut line"), (CENTROID, "under the cutting arm")):
        with pytest.raises(InfeasiblePinch, match=rule) as refusal:
            CuttingTask(SMALL, FLS, 2, pinch_points=point)
        assert_names_the_rule(str(refusal.value), rule)
        assert "\n" not in str(refusal.value)
    task = CuttingTask(SMALL, FLS, 2, pinch_points=[CENTROID, [np.nan, np.nan]], allow_infeasible_pinch=True)
    assert task.pinch_problems[0].startswith("under the cutting arm") and task.pinch_problems[1] is None
    assert CuttingTask(SMALL, FLS, 2, pinch_points=FEASIBLE).pinch_problems == [None, None]
    short = ArmModel(length_mm=5.0)
    assert CuttingTask(SMALL, FLS, 1, pinch_points=CENTROID, arm=short).pinch_problems == [None]


def test_cutting_task_refuses_an_infeasible_pinch_before_it_builds_a_simulator(monkeypatch):
    def built(*args, **kwargs):
        raise AssertionError("a simulator was built for a task refused")

    monkeypatch.setattr(Simulator, "checked", built)
    with pytest.raises(InfeasiblePinch, match="on the cut line"):
        CuttingTask(SMALL, FLS, 2, pinch_points=ON_CUT)


def test_envs_refuse_an_infeasible_pinch_unless_allowed():
    with pytest.raises(ValueError, match="under the cutting arm"):
        gym.make(ENV_ID, contour="fls-circle", resolution=13, device="cpu", pinch_point=CENTROID)
    with pytest.raises(ValueError, match="on the cut line"):
        gym.make_vec(
            ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", contour="fls-circle", resolution=13,
            device="cpu", pinch_point=ON_CUT,
        )  # fmt: skip
    env = gym.make(
        ENV_ID,
        contour="fls-circle",
        resolution=13,
        device="cpu",
        pinch_point=CENTROID,
        allow_infeasible_pinch=True,
    )
    assert env.unwrapped.scene.task.pinch_problems[0].startswith("under the cutting arm")
    _, info = env.reset(seed=0)  # the env's infos say so: at reset and with the episode's score
    assert info["pinch_feasible"] is False and info["pinch_problem"].startswith("under the cutting arm")
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        done = terminated or truncated
    assert info["pinch_feasible"] is False and "error_vertices" in info
    options = PatternCutOptions(pinch_point=CENTROID, allow_infeasible_pinch=True, arm=ArmModel(3.0, 15.0))
    again = PatternCutOptions.from_dict(json.loads(json.dumps(options.to_dict())))
    assert again.allow_infeasible_pinch and again.arm == ArmModel(3.0, 15.0)
    assert PatternCutOptions.from_dict(PatternCutOptions().to_dict()).arm == ArmModel()  # inf as null


def test_library_pipelines_refuse_an_infeasible_pinch_before_any_work(tmp_path):
    with pytest.raises(InfeasiblePinch, match="on the cut line"):
        compare_policies(FLS, ["none", "fixed"], config=SMALL, pinch=ON_CUT)
    with pytest.raises(InfeasiblePinch, match="under the cutting arm"):
        evaluate_suite([FLS], [Method("fixed", pinches=[np.array(CENTROID)])], 1, SMALL)
    job = OptimizeJob(contour="fls-circle", pinch=CENTROID, candidates=2, trials=1, sim=SMALL)
    with pytest.raises(InfeasiblePinch, match="under the cutting arm"):
        optimize_contour(job, tmp_path / "optimize")
    assert not (tmp_path / "optimize" / "results.json").exists()
    report = compare_policies(
        FLS, ["none", "fixed"], config=SMALL, pinch=CENTROID, allow_infeasible_pinch=True
    )
    fixed = report["results"]["fixed"]
    assert fixed["pinch_feasible"] is False and fixed["pinch_problem"].startswith("under the cutting arm")
    assert report["results"]["none"]["pinch_feasible"] is None


@pytest.mark.parametrize(
    ("point", "rule"), [(ON_CUT, "on the cut line"), (CENTROID, "under the cutting arm")]
)
def test_simulate_refuses_an_infeasible_pinch_in_one_line(point, rule, capfd):
    pinch = ",".join(f"{v:g}" for v in point)
    message = refused(
        ["simulate", "--contour", "fls-circle", "--policy", "none,fixed", "--pinch", pinch, *SHEET], capfd
    )
    assert_names_the_rule(message, rule)


def test_simulate_marks_an_allowed_infeasible_pinch_and_keeps_a_feasible_one(tmp_path, capfd):
    args = [
        "simulate",
        "--contour",
        "fls-circle",
        "--policy",
        "none,fixed,analytic",
        *SHEET,
        "--set",
        "plots=false",
    ]
    out = tmp_path / "infeasible.json"
    code, stdout, stderr = invoke([*args, "--pinch", "50,50", *ALLOW, "--json", str(out)])
    assert code == 0, stderr
    rows = {
        line.split()[0]: line
        for line in stdout.splitlines()
        if line.startswith(("none", "fixed", "analytic"))
    }
    assert rows["fixed"].endswith("[infeasible pinch]") and rows["analytic"].endswith("[infeasible pinch]")
    assert "[infeasible pinch]" not in rows["none"]
    assert "infeasible pinch (fixed, analytic): under the cutting arm" in stdout
    results = json.loads(out.read_text())["results"]
    assert (
        results["fixed"]["pinch_feasible"] is False
        and "under the cutting arm" in results["fixed"]["pinch_problem"]
    )
    out = tmp_path / "feasible.json"
    code, stdout, stderr = invoke([*args, "--pinch", "83,83", "--json", str(out)])
    assert code == 0, stderr
    assert "infeasible" not in stdout
    results = json.loads(out.read_text())["results"]
    assert results["fixed"]["pinch_feasible"] is True and results["fixed"]["pinch_problem"] is None
    message = refused([*args, *ALLOW], capfd)  # without a pinch point there is nothing to allow
    assert "allow_infeasible_pinch: read with a pinch point (--pinch) only" in message


@pytest.fixture(scope="module")
def infeasible_run(tmp_path_factory):
    """A tiny training at fls-circle's centroid, under the cutting arm, allowed: (run directory, stdout)."""
    run = tmp_path_factory.mktemp("infeasible") / "fls-circle"
    args = ["train", "--contour", "fls-circle", "--pinch", "50,50", *SHEET, *TINY_TRAINING, *ALLOW]
    code, stdout, stderr = invoke([*args, "--out", str(run)])
    assert code == 0, stderr
    return run, stdout


@pytest.mark.parametrize(
    ("point", "rule"), [("25,50", "on the cut line"), ("50,50", "under the cutting arm")]
)
def test_train_refuses_an_infeasible_pinch_before_any_work(point, rule, tmp_path, capfd):
    out = tmp_path / "run"
    message = refused(
        ["train", "--contour", "fls-circle", "--pinch", point, *SHEET, "--out", str(out)], capfd
    )
    assert_names_the_rule(message, rule)
    assert not out.exists()


def test_train_marks_an_allowed_infeasible_pinch_in_its_output_and_files(infeasible_run):
    run, stdout = infeasible_run
    evaluation_line = next(line for line in stdout.splitlines() if line.startswith("evaluation"))
    assert evaluation_line.endswith("[infeasible pinch]")
    assert "infeasible pinch (rl): under the cutting arm" in stdout
    for name in ("summary.json", "evaluation.json"):
        data = json.loads((run / name).read_text())
        assert data["pinch_feasible"] is False and data["pinch_problem"].startswith("under the cutting arm")
    assert json.loads((run / "options.json").read_text())["allow_infeasible_pinch"] is True


def test_evaluate_refuses_checkpoints_at_an_infeasible_pinch_unless_allowed(infeasible_run, tmp_path, capfd):
    run, _ = infeasible_run
    args = ["evaluate", "--contours", "fls-circle", "--methods", "none,rl", "--checkpoints", str(run.parent)]
    args += ["--trials", "1", *SHEET, "--set", "plan=false", "--set", "plots=false"]
    message = refused([*args, "--out", str(tmp_path / "refused")], capfd)
    assert "under the cutting arm" in message and str(run) in message and "allow_infeasible_pinch" in message
    out = tmp_path / "allowed"
    code, stdout, stderr = invoke([*args, *ALLOW, "--out", str(out)])
    assert code == 0, stderr
    row = json.loads((out / "results.json").read_text())["rows"][0]
    assert row["rl_pinch_feasible"] is False and row["rl_pinch_problem"].startswith("under the cutting arm")
    assert "(infeasible pinch)" in (out / "results.md").read_text() and "(infeasible pinch)" in stdout


def test_robustness_refuses_a_run_at_an_infeasible_pinch_unless_allowed(infeasible_run, tmp_path, capfd):
    run, _ = infeasible_run
    args = ["robustness", "--run", str(run), "--study", "noise", "--methods", "none", "--trials", "1"]
    args += ["--set", "values=[0.03]", "--set", "plots=false"]
    message = refused([*args, "--out", str(tmp_path / "refused")], capfd)
    assert "under the cutting arm" in message and "rl's" in message
    out = tmp_path / "allowed"
    code, stdout, stderr = invoke([*args, *ALLOW, "--out", str(out)])
    assert code == 0, stderr
    report = json.loads((out / "robustness-noise.json").read_text())
    assert report["infeasible_pinches"]["rl"].startswith("under the cutting")
    assert "rl (infeasible)" in stdout and "infeasible pinch (rl)" in stdout


def test_export_records_an_infeasible_pinch_in_the_metadata(infeasible_run, tmp_path):
    import onnx_ir

    run, _ = infeasible_run
    code, stdout, stderr = invoke(["export", str(run), "--out", str(tmp_path / "exported")])
    assert code == 0, stderr
    assert "infeasible pinch (policy): under the cutting arm" in stdout
    metadata = onnx_ir.load(str(tmp_path / "exported" / "policy.onnx")).metadata_props
    assert metadata["warpcut.pinch_feasible"] == "false"
    assert metadata["warpcut.pinch_problem"].startswith("under the cutting arm")


def test_optimize_refuses_an_infeasible_pinch_unless_allowed(tmp_path, capfd):
    args = ["optimize", "--contour", "fls-circle", "--trials", "1", "--set", "candidates=2", *SHEET]
    args += ["--estimator", "tape", "--iterations", "1", "--set", "grad.trials=1"]
    args += ["--set", "grad.validation_trials=0"]
    message = refused([*args, "--pinch", "25,50", "--out", str(tmp_path / "refused")], capfd)
    assert_names_the_rule(message, "on the cut line")
    out = tmp_path / "allowed"
    code, stdout, stderr = invoke([*args, "--pinch", "50,50", *ALLOW, "--out", str(out)])
    assert code == 0, stderr
    report = json.loads((out / "results.json").read_text())
    assert report["pinch_feasible"] is False and report["pinch_problem"].startswith("under the cutting arm")
    assert report["evaluation"]["fixed"]["pinch_feasible"] is False
    assert "[infeasible pinch]" in next(line for line in stdout.splitlines() if line.startswith("fixed"))
    plan = json.loads((out / "fls-circle.json").read_text())  # the optimised plan's own file
    assert plan["pinch_feasible"] is False and plan["pinch_problem"].startswith("under the cutting arm")


def test_run_marks_the_analytic_centroid_where_it_is_infeasible(tmp_path):
    out = tmp_path / "run"
    args = ["run", "--contour", "fls-circle", "--policy", "fixed", *SHEET, "--set", "candidates=2"]
    args += ["--set", "trials=1", "--set", "analytic_pinch=centroid", "--set", "plots=false"]
    code, stdout, stderr = invoke([*args, "--out", str(out)])
    assert code == 0, stderr
    row = json.loads((out / "results.json").read_text())["rows"][0]
    assert row["analytic_pinch_feasible"] is False and row["fixed_pinch_feasible"] is True
    assert "[infeasible pinch]" in next(line for line in stdout.splitlines() if line.startswith("analytic"))
    assert "[infeasible pinch]" not in next(line for line in stdout.splitlines() if line.startswith("fixed"))
