"""``warpcut export``: any run directory (train, run, evaluate), and ONNX metadata that says what the
inputs and outputs mean."""

import json

import numpy as np
import onnx_ir
import pytest
from click.testing import CliRunner

from agents.cli import main
from agents.export import export_run, policy_runs
from agents.pipeline import evaluate_table, run_pipeline
from envs.observations import observation_names
from warpcut.sim.config import SimConfig

SMALL = SimConfig(resolution=13)
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_an_evaluate_directory_exports_every_contours_policy_with_metadata(tmp_path):
    out = tmp_path / "table"
    evaluate_table(["circle-small", "wave-1"], out, methods=["rl"], trials=1, config=SMALL, plan=False,
                   iterations=1, num_envs=4)  # fmt: skip
    assert [run.name for run, _ in policy_runs(out)] == ["circle-small", "wave-1"]
    exported = export_run(out)
    assert [e["onnx"] for e in exported] == [
        out / "exported" / n / "policy.onnx" for n in ("circle-small", "wave-1")
    ]
    model = onnx_ir.load(exported[0]["onnx"])
    meta = model.metadata_props
    names = json.loads(meta["warpcut.observations"])
    scenario = json.loads(meta["warpcut.scenario"])
    assert names == observation_names(scenario["num_fiducials"], True) and names[:2] == ["time", "grasp_dx"]
    assert model.graph.inputs[0].shape[1] == len(names)
    actions = json.loads(meta["warpcut.actions"])
    assert actions[0].startswith("0: stay") and actions[1].startswith("1: +x") and len(actions) == 7
    assert scenario["contour"] == "circle-small" and meta["warpcut.checkpoint"].endswith(".pt")

    code = CliRunner().invoke(
        main, ["export", str(out), "--out", str(tmp_path / "x")], catch_exceptions=False
    )
    assert code.exit_code == 0 and f"exported evaluate {out}: wave-1's policy" in code.output
    assert (tmp_path / "x" / "wave-1" / "policy.pt").is_file()


def test_a_run_directory_exports_the_chosen_candidates_policy(tmp_path):
    report = run_pipeline("circle-small", tmp_path, candidates=2, rl_candidates=2, iterations=1, trials=1,
                          num_envs=4, config=SMALL)  # fmt: skip
    chosen = tmp_path / report.candidates[report.chosen_candidate]["run"]
    ((run, what),) = policy_runs(tmp_path)
    assert run == chosen and "chosen pinch candidate" in what
    (exported,) = export_run(tmp_path)
    assert exported["onnx"] == chosen / "exported" / "policy.onnx"
    scenario = json.loads(onnx_ir.load(exported["onnx"]).metadata_props["warpcut.scenario"])
    assert np.allclose(scenario["pinch_point"], report.candidates[report.chosen_candidate]["pinch"])


def test_a_directory_without_a_policy_says_what_would_do(tmp_path):
    evaluate_table("circle-small", tmp_path, methods=["none"], trials=1, config=SMALL, plan=False)
    with pytest.raises(ValueError, match="holds no trained policy; give a run directory of 'warpcut train'"):
        policy_runs(tmp_path)
