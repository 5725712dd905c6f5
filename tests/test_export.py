"""``warpcut export``: any run directory (train, run, evaluate) or checkpoint, ONNX metadata that says what
the inputs and outputs mean and builds the env the policy acts in, and an exported policy that runs in
onnxruntime on the env as Gymnasium makes it."""

import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import onnx_ir
import onnxruntime
import pytest
import torch
from click.testing import CliRunner
from tensordict import TensorDict

from agents.cli import main
from agents.config import TrainConfig
from agents.es.config import EsConfig
from agents.export import export_run
from agents.jobs import EvaluateJob, RunJob
from agents.pipelines import evaluate_table, run_pipeline
from agents.policies import load_policy, policy_runs
from envs import ENV_ID
from envs.observations import observation_names
from warpcut.sim.config import SimConfig

SMALL = SimConfig(resolution=13)
TINY = TrainConfig(algo="es", num_envs=4, iterations=1, validation_trials=0, es=EsConfig(population=4))
"""es on 4 envs for one iteration."""
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def invoke(args):
    result = CliRunner().invoke(main, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return result.output


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A tiny run of es on the env's defaults on a small sheet, exported."""
    run = tmp_path_factory.mktemp("export") / "run"
    invoke(
        ["train", "--contour", "circle-small", "--set", "sim.resolution=13", "--num-envs", "8"]
        + [
            "--set",
            "train.algo=es",
            "--set",
            "train.es.population=4",
            "--iterations",
            "2",
            "--set",
            "eval_trials=1",
        ]
        + ["--set", "train.validation_trials=2", "--set", "plots=false", "--no-progress", "--out", str(run)]
    )
    output = invoke(["export", str(run)])
    assert f"exported train run {run}" in output
    return run


def onnx_policy(path):
    """``obs (batch, n) -> actions (batch, m)`` of an exported ONNX policy, run by onnxruntime."""
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (given,) = session.get_inputs()

    def act(obs: np.ndarray) -> np.ndarray:
        return session.run(None, {given.name: np.asarray(obs, dtype=np.float32).reshape(-1, given.shape[1])})[
            0
        ]

    return act, session


def play(env, act) -> tuple[int, dict]:
    """One whole episode of ``env`` with the policy ``act``: its steps and the last step's info."""
    obs, _ = env.reset(seed=0)
    steps, done, info = 0, False, {}
    while not done:
        (action,) = act(obs[None])
        assert env.action_space.contains(np.clip(action, -1, 1).astype(env.action_space.dtype))
        obs, reward, terminated, truncated, info = env.step(action)
        assert np.isfinite(reward) and np.all(np.isfinite(obs))
        steps, done = steps + 1, terminated or truncated
    return steps, info


def test_the_exported_policy_runs_in_onnxruntime_on_the_env_its_metadata_makes(trained):
    path = trained / "exported" / "policy.onnx"
    meta = onnx_ir.load(path).metadata_props
    options = json.loads(meta["warpcut.options"])
    assert options["contour"] == "circle-small" and options["sim_config"]["resolution"] == 13
    assert options["device"] is None
    env = gym.make(ENV_ID, **options)  # the metadata alone builds the env the policy was trained in
    assert ENV_ID == "warpcut/PatternCut-v0"
    act, session = onnx_policy(path)
    names = json.loads(meta["warpcut.observations"])
    assert names == observation_names(options["num_fiducials"], options["contour_features"])
    assert session.get_inputs()[0].shape[1] == len(names) == env.observation_space.shape[0]
    actions = json.loads(meta["warpcut.actions"])
    assert actions == [f"grasp d{axis} / max_step_mm, in [-1, 1]" for axis in "xyz"]
    assert isinstance(env.action_space, gym.spaces.Box) and env.action_space.shape == (len(actions),)
    # onnxruntime computes what the trained actor does (observation normalisation included).
    obs, _ = env.reset(seed=1)
    actor = load_policy(trained)
    expected = actor(TensorDict({"policy": torch.as_tensor(obs[None])}, batch_size=[1])).detach().numpy()
    np.testing.assert_allclose(act(obs[None]), expected, atol=1e-5)
    steps, info = play(env, act)  # the whole cut: its score comes with the last step
    assert steps > 10 and np.isfinite(info["error_vertices"])


def test_the_default_trainings_policy_runs_on_the_default_env(trained):
    """The env's defaults are the default learner's: its exported policy runs on
    ``gymnasium.make(ENV_ID, contour=...)`` with no other options (47 observations, 3 continuous moves)."""
    env = gym.make(ENV_ID, contour="circle-small")
    assert env.observation_space.shape == (47,)
    assert isinstance(env.action_space, gym.spaces.Box) and env.action_space.shape == (3,)
    act, session = onnx_policy(trained / "exported" / "policy.onnx")
    assert session.get_inputs()[0].shape[1] == 47 and session.get_outputs()[0].shape[1] == 3
    steps, info = play(env, act)
    assert steps > 0 and np.isfinite(info["error_vertices"])


def test_the_readmes_lines_play_an_exported_policy_on_the_env_its_metadata_makes(trained, capsys):
    """The README's snippet, as written (the run's path put in), loads the ONNX file, builds the env from
    its metadata and cuts with it."""
    import re

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    (snippet,) = [b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "InferenceSession" in b]
    path = trained / "exported" / "policy.onnx"
    exec(compile(snippet.replace("RUN/exported/policy.onnx", str(path)), "README.md", "exec"), {})
    printed = capsys.readouterr().out.strip()
    assert re.fullmatch(r"\d+\.\d vertices", printed), printed


def test_a_finished_run_exports_without_a_note_and_says_so_in_the_metadata(trained):
    output = invoke(["export", str(trained), "--out", str(trained / "again")])
    assert "unfinished" not in output and "note:" not in output
    meta = onnx_ir.load(str(trained / "again" / "policy.onnx")).metadata_props
    training = {"status": "completed", "iterations": 2, "target_iterations": 2, "checkpoint": "best.pt"}
    assert json.loads(meta["warpcut.training"]) == training


@pytest.mark.parametrize(
    ("summary", "how"),
    [
        ("interrupted", "(interrupted; trained 1 of 2 iterations)"),
        (None, "(no summary.json: killed, or still training; trained 2 of 2 iterations)"),
    ],
)
def test_an_unfinished_run_exports_with_a_note_and_says_so_in_the_metadata(trained, tmp_path, summary, how):
    """A run whose training was interrupted (its summary says so) or killed (no summary) is exported, its
    output and metadata saying it is unfinished and which checkpoint was exported."""
    run = tmp_path / "run"
    shutil.copytree(trained, run, ignore=shutil.ignore_patterns("exported", "again"))
    if summary is None:
        (run / "summary.json").unlink()
    else:
        data = json.loads((run / "summary.json").read_text())
        (run / "summary.json").write_text(json.dumps({**data, "status": summary, "iterations": 1}))
    output = invoke(["export", str(run), "--out", str(tmp_path / "out")])
    notes = [line for line in output.splitlines() if line.startswith("note:")]
    assert notes == [f"note: {run} is unfinished {how}; exported its best checkpoint so far (best.pt)"]
    meta = onnx_ir.load(str(tmp_path / "out" / "policy.onnx")).metadata_props
    training = json.loads(meta["warpcut.training"])
    assert training["status"] == (summary or "unfinished") and training["checkpoint"] == "best.pt"
    assert training["target_iterations"] == 2


def test_a_checkpoint_describes_its_own_policy(trained, tmp_path):
    """A checkpoint alone (no run directory beside it) rebuilds and exports its policy: it holds the actor's
    config, its observation groups and shapes and its actions."""
    alone = tmp_path / "alone.pt"
    shutil.copy(trained / "best.pt", alone)
    state = torch.load(alone, weights_only=False)
    policy = state["policy"]
    assert policy["num_actions"] == 3 and policy["obs_shapes"] == {"policy": [47]}
    assert policy["obs_groups"]["actor"] == ["policy"]
    assert policy["actor"]["class_name"] == "agents.models:FeedbackMLPModel"  # es's feedback path
    (exported,) = export_run(alone, tmp_path / "out")
    meta = onnx_ir.load(exported["onnx"]).metadata_props
    assert meta["warpcut.checkpoint"] == str(alone) and "warpcut.options" not in meta  # no run beside it
    obs = np.random.default_rng(0).normal(size=(5, 47)).astype(np.float32)
    ours, _ = onnx_policy(exported["onnx"])
    theirs, _ = onnx_policy(trained / "exported" / "policy.onnx")  # best.pt's too
    np.testing.assert_allclose(ours(obs), theirs(obs), atol=1e-6)


def test_an_evaluate_directory_exports_every_contours_policy_with_metadata(tmp_path):
    out = tmp_path / "table"
    job = EvaluateJob(
        contours=["circle-small", "wave-1"], methods=["rl"], trials=1, sim=SMALL, plan=False, train=TINY
    )
    evaluate_table(job, out)
    assert [run.name for run, _ in policy_runs(out)] == ["circle-small", "wave-1"]
    exported = export_run(out)
    assert [e["onnx"] for e in exported] == [
        out / "exported" / n / "policy.onnx" for n in ("circle-small", "wave-1")
    ]
    model = onnx_ir.load(exported[0]["onnx"])
    meta = model.metadata_props
    names = json.loads(meta["warpcut.observations"])
    options = json.loads(meta["warpcut.options"])
    assert names == observation_names(options["num_fiducials"], True) and names[:2] == ["time", "grasp_dx"]
    assert model.graph.inputs[0].shape[1] == len(names)
    assert len(json.loads(meta["warpcut.actions"])) == 3
    assert options["contour"] == "circle-small" and meta["warpcut.checkpoint"].endswith(".pt")

    output = invoke(["export", str(out), "--out", str(tmp_path / "x")])
    assert f"exported evaluate {out}: wave-1's policy" in output
    assert (tmp_path / "x" / "wave-1" / "policy.pt").is_file()


def test_a_run_directory_exports_the_chosen_candidates_policy(tmp_path):
    job = RunJob(contour="circle-small", candidates=2, rl_candidates=2, trials=1, sim=SMALL, train=TINY)
    report = run_pipeline(job, tmp_path)
    chosen = tmp_path / report.candidates[report.chosen_candidate]["run"]
    ((run, what),) = policy_runs(tmp_path)
    assert run == chosen and "chosen pinch candidate" in what
    (exported,) = export_run(tmp_path)
    assert exported["onnx"] == chosen / "exported" / "policy.onnx"
    options = json.loads(onnx_ir.load(exported["onnx"]).metadata_props["warpcut.options"])
    assert np.allclose(options["pinch_point"], report.candidates[report.chosen_candidate]["pinch"])


def test_a_directory_without_a_policy_says_what_would_do(tmp_path):
    evaluate_table(
        EvaluateJob(contours=["circle-small"], methods=["none"], trials=1, sim=SMALL, plan=False), tmp_path
    )
    with pytest.raises(ValueError, match="holds no trained policy; give a run directory of 'warpcut train'"):
        policy_runs(tmp_path)


def test_export_refuses_an_option_given_twice(tmp_path):
    result = CliRunner().invoke(main, ["export", str(tmp_path), "--out", "a", "--out", "b"])
    assert result.exit_code == 2 and "--out: given twice" in result.output
