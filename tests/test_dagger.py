"""Teachers at scale and the generalist that learns from them: ``warpcut teachers`` (a resumable dataset of
per-contour plans), the suite-like generated kinds, and dagger (agents.dagger): labels that replay the
teacher on its own states and lead back to its path off them, the aggregated dataset, exact resume, and a
generalist trained from a dataset that every command plays."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from agents.dagger.algorithm import teacher_path
from agents.dagger.config import DaggerConfig
from agents.teachers import INDEX_FILE, load_teachers
from tests.cli_runner import invoke, refused
from warpcut.planning.generate import EXTRA_KINDS, generate_contours, resolve_specs
from warpcut.sim.config import SimConfig
from warpcut.validation import ConfigError

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SMALL = ["--set", "sim.resolution=13"]
TEACHER = ["--set", "candidates=2", "--set", "grad.iterations=2", "--set", "grad.validation_trials=2", *SMALL]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Three coarse teachers (a blob, a polygon and a notched shape) of two optimiser steps each."""
    out = tmp_path_factory.mktemp("teachers") / "data"
    code, output, _ = invoke(["teachers", "--count", "3", "--out", str(out), *TEACHER])
    assert code == 0, output
    return out, output


@pytest.fixture(scope="module")
def student(dataset, tmp_path_factory):
    """A dagger generalist of 3 iterations on the dataset."""
    out = tmp_path_factory.mktemp("dagger") / "run"
    code, output, _ = invoke(_student_args(dataset[0], out))
    assert code == 0, output
    return out, output


def _student_args(teachers, out, iterations: int = 3) -> list[str]:
    return [
        "generalist", "--teachers", str(teachers), "--validation-contours", "1", "--iterations",
        str(iterations), "--out", str(out), "--no-progress", "--set", "candidates=2", "--set",
        "train.dagger.updates=5", *SMALL,
    ]  # fmt: skip


def test_the_suite_like_kinds_are_drawn_where_asked_and_named_by_their_specs():
    config = SimConfig(resolution=13)
    drawn = generate_contours(4, "train", 0, config, EXTRA_KINDS)
    assert [c.name.rsplit("-", 1)[-1] for c in drawn] == ["elongated", "edge", "elongated", "edge"]
    for contour in drawn:
        ((spec, again),) = resolve_specs(contour.name, config)
        assert np.array_equal(again.points, contour.points)
    elongated, edge = drawn[0].points, drawn[1].points
    extent = np.linalg.svd(elongated - elongated.mean(0), compute_uv=False)
    assert extent[0] > 2 * extent[1]  # long and thin
    gap = min(edge[:, 0].min(), edge[:, 1].min(), 100 - edge[:, 0].max(), 100 - edge[:, 1].max())
    assert 2.5 < gap < 6.5  # hugs an edge
    # the default streams are as they were: the extra kinds are drawn only where asked
    assert [c.name for c in generate_contours(2, "train", 0, config)] == [
        "gen-train-0-0000-blob", "gen-train-0-0001-polygon",
    ]  # fmt: skip


def test_teachers_builds_a_dataset_a_contour_a_unit(dataset):
    out, output = dataset
    index = json.loads((out / INDEX_FILE).read_text())
    assert index["count"] == 3 and [r["kind"] for r in index["contours"]] == ["blob", "polygon", "notched"]
    assert "done: 3 teachers" in output and "warpcut generalist --teachers" in output
    teachers = load_teachers(out, SimConfig(resolution=13))
    for row, teacher in zip(index["contours"], teachers, strict=True):
        assert teacher.contour.name == row["contour"] and teacher.plan.shape == (row["steps"], 3)
        assert teacher.error == row["error_vertices"] and teacher.still_error == row["still_error_vertices"]
        assert len(teacher.segments) == row["segments"] and np.allclose(teacher.pinch, row["pinch"])


def test_a_dataset_resumes_and_grows_keeping_its_teachers(dataset, tmp_path):
    import shutil

    out = tmp_path / "data"
    shutil.copytree(dataset[0], out)
    before = {p.relative_to(out): p.read_bytes() for p in (out / "teachers").glob("*/*.json")}
    (out / INDEX_FILE).unlink()
    code, output, _ = invoke(["teachers", "--count", "4", "--resume", "--out", str(out), *TEACHER])
    assert code == 0, output
    after = {p.relative_to(out): p.read_bytes() for p in (out / "teachers").glob("*/*.json")}
    assert all(after[name] == data for name, data in before.items())  # read back, not optimised again
    assert len(json.loads((out / INDEX_FILE).read_text())["contours"]) == 4
    changed = ["--set", "candidates=2", "--set", "grad.iterations=3", *SMALL]
    code, output, errors = invoke(["teachers", "--count", "4", "--resume", "--out", str(out), *changed])
    assert code == 2 and "grad.iterations" in errors


def test_a_teacher_path_adds_the_moves_up_under_the_simulators_limits():
    plan = np.array([[2.0, 0, 0], [0.5, 0.5, 0], [-1, 0, 0]], dtype=np.float32)
    path = teacher_path(plan, max_step=1.0, max_displacement=1.2)
    assert np.allclose(path[1], [1, 0, 0])  # clipped to a step
    assert np.isclose(np.linalg.norm(path[2]), 1.2)  # capped in all
    assert np.allclose(path[3], path[2] - [1, 0, 0])


def _labeller(teachers, options, num_envs):
    """A :class:`DAgger` with just what :meth:`DAgger.teacher_moves` reads, for the envs of ``options``."""
    from agents.dagger.algorithm import DAgger

    class Env:
        cfg = options

    Env.num_envs = num_envs
    shell = DAgger.__new__(DAgger)
    shell._path, shell._steps = DAgger._teacher_paths(Env(), teachers)
    shell.max_step, shell.max_displacement, shell.horizon = 1.0, 10.0, 1
    return shell


def test_dagger_labels_replay_the_teacher_on_its_states_and_lead_back_off_them(dataset):
    """An env that plays the labels of its own states moves its grasp along its teacher's path, step for
    step, to the end of its cut: the labels on the teacher's states are its plan's moves. A grasp off the
    path is labelled with the move back toward it."""
    from envs.options import PatternCutOptions
    from envs.vector import PatternCutVecEnv

    config = SimConfig(resolution=13)
    teachers = load_teachers(dataset[0], config)
    options = PatternCutOptions(
        contour=[t.contour for t in teachers], pinch_point=np.array([t.pinch for t in teachers]),
        segments=[[s.tolist() for s in t.segments] for t in teachers], sim_config=config, lookahead=8,
    )  # fmt: skip
    env = PatternCutVecEnv(len(teachers), options)
    labeller = _labeller(str(dataset[0]), options, len(teachers))
    obs, _ = env.reset(seed=0)
    grasps, labels = [], []
    for _ in range(env.scene.task.num_steps):
        raw = torch.as_tensor(obs)
        labels.append(labeller.teacher_moves(raw).numpy())
        grasps.append(obs[:, 1:4] * 10.0)
        obs, *_ = env.step(labels[-1])
    for e, teacher in enumerate(teachers):
        steps = len(teacher.plan)
        path = teacher_path(teacher.plan, 1.0, 10.0)
        played = np.array([g[e] for g in grasps[: steps + 1]])
        assert np.allclose(played, path[: len(played)], atol=1e-4)  # the teacher's path, step for step
        moves = np.array([a[e] for a in labels[:steps]])
        assert np.allclose(moves, np.clip(teacher.plan, -1, 1), atol=1e-4)
    raw = torch.zeros(1, obs.shape[1])
    raw[0, 0] = 0.5
    raw[0, 1:4] = torch.as_tensor(path[len(path) // 2 + 1]) / 10.0 + torch.tensor(
        [0.05, 0.0, 0.0]
    )  # 0.5 mm off
    back = labeller.teacher_moves(raw.repeat(len(teachers), 1))[-1].numpy()
    t = round(0.5 * (len(path) - 1))
    assert np.allclose(back, np.clip(path[t + 1] - raw[0, 1:4].numpy() * 10.0, -1, 1), atol=1e-5)
    labeller.horizon = 4  # a horizon aims 4 steps on, a quarter of the way a step
    ahead = labeller.teacher_moves(raw.repeat(len(teachers), 1))[-1].numpy()
    assert np.allclose(ahead, np.clip((path[t + 4] - raw[0, 1:4].numpy() * 10.0) / 4, -1, 1), atol=1e-5)


def test_dagger_needs_teachers_for_its_contours(dataset, tmp_path, capfd):
    with pytest.raises(ConfigError, match="train.dagger.beta"):
        DaggerConfig(beta=1.5)
    assert "teachers" in refused(
        ["generalist", "--set", "train.algo=dagger", "--out", str(tmp_path / "a")], capfd
    )
    missing = ["generalist", "--teachers", str(tmp_path / "none"), "--out", str(tmp_path / "b"), *SMALL]
    message = refused(missing, capfd)
    assert "no such directory" in message and "warpcut teachers" in message
    message = refused(["generalist", "--teachers", str(dataset[0]), "--generated", "5", "--out",
                       str(tmp_path / "c"), *SMALL], capfd)  # fmt: skip
    assert "generated" in message


def test_a_dagger_generalist_trains_resumes_exactly_and_plays_everywhere(student, dataset, tmp_path):
    from agents.generalist import generalist_settings

    out, output = student
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["algo"] == "dagger" and summary["iterations"] == 3
    assert summary["history"][-1]["dataset"] > summary["history"][0]["dataset"]  # aggregated
    settings = generalist_settings(out)
    assert settings["policy"]["feedback"] and settings["policy"]["scheduled"]
    assert len(settings["training_contours"]) == 3
    code, played, _ = invoke([
        "evaluate", "--contours", "circle-small", "--methods", "none,generalist", "--generalist", str(out),
        "--trials", "1", "--out", str(tmp_path / "eval"), "--set", "candidates=2", *SMALL,
    ])  # fmt: skip
    assert code == 0, played
    # exact resume: 2 iterations, then resumed to 3, ends with the weights of 3 in one go
    from agents.checkpoints import read_checkpoint

    again = tmp_path / "again"
    code, first, _ = invoke(_student_args(dataset[0], again, 2))
    assert code == 0, first
    code, resumed, _ = invoke(
        ["generalist", "--resume", "--iterations", "3", "--out", str(again), "--no-progress"]
    )
    assert code == 0, resumed
    a = read_checkpoint(out / "latest.pt")["actor_state_dict"]
    b = read_checkpoint(again / "latest.pt")["actor_state_dict"]
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_a_dagger_generalist_has_its_own_observation_and_network_unless_given(dataset):
    import yaml

    from agents.config import STUDENT_DEFAULTS

    base = ["generalist", "--teachers", str(dataset[0]), "--print-config"]
    code, printed, _ = invoke(base)
    assert code == 0, printed
    config = yaml.safe_load(printed)
    assert config["train"]["algo"] == "dagger" and config["train"]["dagger"]["teachers"] == str(dataset[0])
    assert config["env"]["num_fiducials"] == STUDENT_DEFAULTS["env.num_fiducials"]
    assert config["train"]["actor_hidden_dims"] == STUDENT_DEFAULTS["train.actor_hidden_dims"]
    code, printed, _ = invoke([*base, "--set", "env.num_fiducials=12"])
    assert code == 0 and yaml.safe_load(printed)["env"]["num_fiducials"] == 12
    code, printed, _ = invoke(["generalist", "--print-config"])  # es's generalist is as it was
    assert (
        yaml.safe_load(printed)["train"]["algo"] == "es"
        and yaml.safe_load(printed)["env"]["num_fiducials"] == 12
    )


def test_teachers_near_a_student_start_from_its_moves_and_a_heavy_tether_keeps_them(student, tmp_path, capfd):
    """Guided policy search's next round: each teacher starts from the student's own moves on its cut (and
    records the student's and the still grasp's validation errors); a tether far heavier than any gain keeps
    the student's moves as the teacher; a tether needs a student, and a student must be a generalist."""
    from agents.generalist import load_generalist, student_moves
    from agents.plan_optimizer.config import GRAD_SEED_OFFSET

    out = tmp_path / "near"
    near = ["--set", f"near={student[0]}", "--set", "tether=1e6"]
    code, output, _ = invoke(["teachers", "--count", "2", "--out", str(out), *TEACHER, *near])
    assert code == 0, output
    index = json.loads((out / INDEX_FILE).read_text())
    assert "mean_start_error_vertices" in index
    config = SimConfig(resolution=13)
    generalist = load_generalist(student[0])
    for row, teacher in zip(index["contours"], load_teachers(out, config), strict=True):
        assert row["error_vertices"] == row["start_error_vertices"]  # the student's moves, kept
        moves = student_moves(
            generalist, teacher.contour, teacher.pinch, teacher.segments, config, GRAD_SEED_OFFSET
        )
        np.testing.assert_array_equal(teacher.plan[: len(moves)], np.clip(moves, -1.0, 1.0))
    message = refused(
        ["teachers", "--count", "2", "--out", str(tmp_path / "a"), *TEACHER, "--set", "tether=0.1"], capfd
    )
    assert "TeachersJob.tether" in message and "near" in message
    message = refused(
        ["teachers", "--count", "2", "--out", str(tmp_path / "b"), *TEACHER, "--set", f"near={tmp_path}"],
        capfd,
    )
    assert "generalist" in message and "warpcut generalist" in message
