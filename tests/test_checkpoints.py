"""Damaged, missing and mismatched run files: every checkpoint, options file and figure a run reads or
writes fails with one line naming the file and the fix; resume finds the newest readable checkpoint; a
checkpoint describes its own policy."""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from dummy_env import ReachEnv
from tensordict import TensorDict

from agents.checkpoints import (
    BEST_CHECKPOINT,
    LATEST_CHECKPOINT,
    latest_checkpoint,
    policy_checkpoint,
    read_checkpoint,
    resume_checkpoint,
)
from agents.cli import main
from agents.config import TrainConfig
from agents.config_io import to_plain
from agents.es.config import EsConfig
from agents.export import export_policy
from agents.jobs import TrainJob
from agents.policies import check_policy_run, load_options, load_policy
from agents.ppo.config import PpoConfig
from agents.training import train, train_contour
from envs.options import EnvConfig, PatternCutOptions
from warpcut.contours import Contour, load_contour
from warpcut.sim.config import SimConfig

NUM_ENVS = 8


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def tiny(**overrides) -> TrainConfig:
    """PPO on the dummy env: a few short iterations from a uniform start."""
    ppo = PpoConfig(num_steps_per_env=8, stay_prior=0.0)
    return TrainConfig(**{"algo": "ppo", "num_envs": NUM_ENVS, "iterations": 3, "ppo": ppo, **overrides})


@pytest.fixture(scope="module")
def dummy_run(tmp_path_factory):
    """A dummy-env run with a validated best.pt, latest.pt and model_0..2.pt; copy it before damaging it."""
    run = tmp_path_factory.mktemp("dummy") / "run"
    train(ReachEnv(NUM_ENVS), tiny(save_interval=1), run, progress=False, validate=lambda actor: 1.0)
    return run


@pytest.fixture
def run(dummy_run, tmp_path):
    return shutil.copytree(dummy_run, tmp_path / "run")


def damage(path, kind: str) -> None:
    data = path.read_bytes()
    path.write_bytes({"empty": b"", "truncated": data[: len(data) // 2], "text": b"not a checkpoint\n"}[kind])


class WiderReach(ReachEnv):
    """The reach task observing one more (constant) value: a policy of ReachEnv does not fit it."""

    def get_observations(self) -> TensorDict:
        obs = super().get_observations()
        wider = torch.cat([obs["policy"], torch.ones(self.num_envs, 1)], dim=-1)
        return TensorDict({"policy": wider}, batch_size=[self.num_envs])


def cli_error(capfd, *args) -> str:
    """Run ``warpcut ARGS`` expecting a clean error: its one stderr line."""
    with pytest.raises(SystemExit) as exit_info:
        main.main(args=list(args), prog_name="warpcut")
    err = capfd.readouterr().err.strip()
    assert exit_info.value.code == 2, err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert err.startswith("error: ")
    return err


# --- damaged checkpoints ------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["empty", "truncated", "text"])
def test_a_damaged_best_checkpoint_is_named_with_the_fix(run, kind, capfd):
    best = run / BEST_CHECKPOINT
    damage(best, kind)
    with pytest.raises(ValueError, match="not a readable checkpoint") as error:
        load_policy(run)
    message = str(error.value)
    assert message.startswith(f"{best}: ") and "delete it to use the run's last policy (latest.pt)" in message
    # The CLI: one line, not "interrupted" (an EOFError click takes for Ctrl-D) nor a traceback.
    err = cli_error(capfd, "export", str(run))
    assert f"{best}: not a readable checkpoint" in err
    best.unlink()  # the fix the message gives
    assert policy_checkpoint(run) == run / LATEST_CHECKPOINT and load_policy(run) is not None


def test_a_damaged_checkpoint_given_by_name_suggests_a_readable_one(run):
    damage(run / "model_2.pt", "truncated")
    with pytest.raises(
        ValueError, match=r"model_2.pt: not a readable checkpoint \(truncated or damaged\?\); use "
    ):
        train(ReachEnv(NUM_ENVS), tiny(iterations=4), run, resume=run / "model_2.pt", progress=False)
    with pytest.raises(ValueError, match=r"e\.g\. latest\.pt, the newest readable one"):
        read_checkpoint(run / "model_2.pt")
    damage(run / LATEST_CHECKPOINT, "empty")
    with pytest.raises(ValueError, match=r"e\.g\. model_1\.pt, the newest readable one"):
        read_checkpoint(run / "model_2.pt")
    with pytest.raises(
        ValueError, match=r"latest.pt: not a readable checkpoint \(an empty file: its"
    ) as error:
        load_policy(run / LATEST_CHECKPOINT)
    assert str(error.value).endswith(
        "delete it to fall back to model_1.pt (the newest readable checkpoint), or retrain"
    )
    with pytest.raises(ValueError, match="is a directory, not a checkpoint file"):
        read_checkpoint(run)


def test_exporting_a_file_that_is_not_a_checkpoint_is_one_line(run, tmp_path, capfd):
    notes = tmp_path / "notes.txt"
    notes.write_text("hello\n")
    err = cli_error(capfd, "export", str(notes))
    assert f"{notes}: not a readable checkpoint (not a PyTorch checkpoint file)" in err
    assert "give a run directory written by 'warpcut train'" in err
    err = cli_error(capfd, "train", "--resume", str(notes))
    assert str(notes.parent) in err
    # A file where the output directory should be.
    err = cli_error(capfd, "export", str(run), "--out", str(notes / "sub"))
    assert f"--out: cannot write {notes / 'sub'} ({notes} is not a directory)" in err
    (run / "exported" / "policy.pt").mkdir(parents=True)
    with pytest.raises(ValueError, match=r"policy.pt: is a directory"):
        export_policy(run)


def test_a_checkpoint_describes_its_own_policy(run, tmp_path, capfd):
    """Every checkpoint holds its policy's description (the actor's rsl-rl config, its observation shapes and
    actions) beside its weights: the policy loads, plays and exports from the .pt file alone, copied away
    from its run."""
    state = read_checkpoint(run / BEST_CHECKPOINT)
    assert state["algo"] == "ppo"
    assert state["policy"] == {
        "actor": tiny().to_rsl_rl(3)["actor"],
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "obs_shapes": {"policy": [2]},
        "num_actions": 1,
        "num_action_choices": 3,
    }
    alone = tmp_path / "elsewhere" / "any-name.pt"
    alone.parent.mkdir()
    shutil.copy(run / BEST_CHECKPOINT, alone)
    actor, original = load_policy(alone), load_policy(run)
    obs = TensorDict({"policy": torch.randn(16, 2) * 2.0}, batch_size=[16])
    with torch.inference_mode():
        assert torch.equal(actor(obs), original(obs))
    for name, value in original.state_dict().items():
        assert torch.equal(actor.state_dict()[name], value), name
    with pytest.raises(SystemExit) as exit_info:
        main.main(args=["export", str(alone)], prog_name="warpcut")
    assert exit_info.value.code == 0, capfd.readouterr().err
    assert (alone.parent / "exported" / "policy.onnx").is_file()


def test_resuming_with_another_observation_size_names_both(run):
    before = (run / LATEST_CHECKPOINT).read_bytes()
    with pytest.raises(ValueError, match=r"latest.pt: policy expects 2 observations, the env gives 3"):
        train(WiderReach(NUM_ENVS), tiny(iterations=4), run, resume=run, progress=False)
    assert (run / LATEST_CHECKPOINT).read_bytes() == before  # not rewritten by the failed resume


def test_a_checkpoint_whose_description_does_not_fit_its_weights_is_named(run):
    path = run / BEST_CHECKPOINT
    state = torch.load(path, weights_only=True)
    state["policy"]["obs_shapes"]["policy"] = [5]
    torch.save(state, path)
    with pytest.raises(
        ValueError,
        match=r"best.pt: policy expects 2 observations, its description gives 5; the file is damaged",
    ):
        load_policy(run)
    state["policy"] = {"actor": {}}
    torch.save(state, path)
    with pytest.raises(ValueError, match=r"best.pt: its policy description cannot be read \(KeyError"):
        load_policy(run)
    del state["policy"]
    torch.save(state, path)
    with pytest.raises(
        ValueError,
        match=r"best.pt: not a readable checkpoint \(not a checkpoint of 'warpcut train': no policy\)",
    ):
        load_policy(run)


# --- resume from the newest readable checkpoint --------------------------------------------------------


def test_a_run_without_latest_resumes_from_its_newest_model(run, capsys):
    (run / LATEST_CHECKPOINT).unlink()
    (run / BEST_CHECKPOINT).unlink()
    assert latest_checkpoint(run) == run / "model_2.pt" and policy_checkpoint(run) == run / "model_2.pt"
    load_policy(run)
    summary = train(ReachEnv(NUM_ENVS), tiny(iterations=4), run, resume=run, progress=False)
    assert summary["iterations"] == 4 and summary["resumed_from"] == str(run / "model_2.pt")
    assert "latest.pt missing; resuming from model_2.pt" in summary["resume_note"]
    assert "warning:" in capsys.readouterr().err


@pytest.mark.parametrize("kind", ["empty", "truncated"])
def test_a_damaged_latest_falls_back_to_the_newest_readable_model(run, kind, capsys):
    damage(run / LATEST_CHECKPOINT, kind)
    damage(run / "model_2.pt", "text")
    checkpoint, state, note = resume_checkpoint(run)
    assert checkpoint == run / "model_1.pt" and state["infos"]["iterations_done"] == 2
    why = {"empty": "an empty file: its write was cut short", "truncated": "truncated or damaged?"}[kind]
    assert note == f"{run}: latest.pt {why}; resuming from model_1.pt (model_2.pt unreadable)"
    summary = train(ReachEnv(NUM_ENVS), tiny(iterations=3), run, resume=run, progress=False)
    assert summary["iterations"] == 3 and summary["checkpoint"] == "model_2.pt"
    assert "resuming from model_1.pt" in capsys.readouterr().err
    assert read_checkpoint(run / LATEST_CHECKPOINT)["infos"]["iterations_done"] == 3  # rewritten whole


def test_a_stale_latest_gives_way_to_a_newer_model(run):
    shutil.copy(run / "model_0.pt", run / LATEST_CHECKPOINT)  # as if writing latest.pt had failed since
    checkpoint, _, note = resume_checkpoint(run)
    assert checkpoint == run / "model_2.pt" and "latest.pt older than model_2.pt" in note


def test_a_run_with_no_readable_checkpoint_says_so(run, tmp_path):
    for path in run.glob("*.pt"):
        damage(path, "empty")
    with pytest.raises(ValueError, match=r"no readable checkpoint to resume from \(latest.pt: an empty file"):
        resume_checkpoint(run)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileNotFoundError, match="no checkpoint to resume from"):
        resume_checkpoint(empty)


# --- a full disk ----------------------------------------------------------------------------------------


def full_disk(monkeypatch, module: str, names: set[str]) -> None:
    """Fill the disk for the files named in ``names``: syncing their temporary files (``write_atomic``'s
    ``.NAME.*.tmp``) fails with ENOSPC, as a full disk makes it. ``module`` is the writer under test."""
    real = os.fsync

    def fsync(fd):
        name = Path(os.readlink(f"/proc/self/fd/{fd}")).name
        if any(name.startswith(f".{n}.") for n in names):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)


def test_a_full_disk_while_saving_keeps_the_last_good_checkpoint(tmp_path, monkeypatch):
    run = tmp_path / "run"
    full_disk(monkeypatch, "agents.training", {"model_2.pt"})
    with pytest.raises(ValueError) as error:
        train(ReachEnv(NUM_ENVS), tiny(save_interval=1), run, progress=False)
    assert str(error.value) == (
        f"{run / 'model_2.pt'}: not written, the disk is full; the previous checkpoint model_1.pt is intact: "
        f"free space, then resume from {run}"
    )
    assert isinstance(error.value.__cause__, OSError) and error.value.__cause__.errno == errno.ENOSPC
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["checkpoint"] == "model_1.pt"
    assert "the disk is full" in summary["error"]
    assert read_checkpoint(run / LATEST_CHECKPOINT)["infos"]["iterations_done"] == 2
    assert not list(run.glob(".*.tmp"))

    monkeypatch.undo()
    summary = train(ReachEnv(NUM_ENVS), tiny(iterations=4, save_interval=1), run, resume=run, progress=False)
    assert summary["status"] == "completed" and summary["iterations"] == 4


def test_a_full_disk_at_best_keeps_the_best_on_disk_in_the_summary(tmp_path, monkeypatch):
    run = tmp_path / "run"
    errors = iter([5.0, 6.0, 3.0])  # iterations 0 (the best so far), 1, then 2 after resuming
    train(ReachEnv(NUM_ENVS), tiny(iterations=1), run, progress=False, validate=lambda actor: next(errors))
    full_disk(monkeypatch, "agents.training", {BEST_CHECKPOINT})
    with pytest.raises(ValueError, match=r"best.pt: not written, the disk is full; the previous best.pt is"):
        train(
            ReachEnv(NUM_ENVS), tiny(iterations=2, validation_interval=1), run, resume=run, progress=False,
            validate=lambda actor: next(errors),
        )  # fmt: skip
    summary = json.loads((run / "summary.json").read_text())
    assert summary["best"]["iterations"] == 0 and summary["best"]["validation_error"] == 5.0
    assert read_checkpoint(run / BEST_CHECKPOINT)["infos"]["best_error"] == 5.0


def test_a_full_disk_at_latest_still_records_the_model_written(tmp_path, monkeypatch):
    run = tmp_path / "run"
    train(ReachEnv(NUM_ENVS), tiny(iterations=1), run, progress=False)
    full_disk(monkeypatch, "agents.training", {LATEST_CHECKPOINT})
    with pytest.raises(
        ValueError, match=r"latest.pt: not written, the disk is full; model_2.pt \(the newest"
    ):
        train(ReachEnv(NUM_ENVS), tiny(iterations=3), run, resume=run, progress=False)
    assert json.loads((run / "summary.json").read_text())["checkpoint"] == "model_2.pt"
    monkeypatch.undo()
    checkpoint, _, note = resume_checkpoint(run)
    assert checkpoint == run / "model_2.pt" and "latest.pt older than model_2.pt" in note


def test_a_full_disk_at_the_summary_is_named_and_never_hides_the_first_error(tmp_path, monkeypatch):
    full_disk(monkeypatch, "agents.training", {"summary.json"})
    with pytest.raises(
        ValueError, match=r"summary.json: not written, the disk is full; the newest checkpoint"
    ):
        train(ReachEnv(NUM_ENVS), tiny(iterations=1), tmp_path / "a", progress=False)
    full_disk(monkeypatch, "agents.training", {"model_0.pt", "summary.json"})
    with pytest.raises(
        ValueError, match=r"model_0.pt: not written, the disk is full; no checkpoint"
    ) as error:
        train(ReachEnv(NUM_ENVS), tiny(iterations=1), tmp_path / "b", progress=False)
    assert any("summary.json: not written" in note for note in error.value.__notes__)


def test_a_full_disk_while_plotting_is_one_line(tmp_path, monkeypatch):
    from agents.plots import plot_learning_curve

    full_disk(monkeypatch, "warpcut.viz.plots", {"learning_curve.svg"})
    history = [{"iteration": 1, "final_error": 0.5, "iteration_steps_per_s": 100.0}]
    with pytest.raises(ValueError, match=r"learning_curve.svg: not written, the disk is full"):
        plot_learning_curve(history, [], tmp_path)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match=r"file: is a file, not a directory for the figures"):
        plot_learning_curve(history, [], tmp_path / "file")


def test_a_file_where_the_run_directory_should_be_is_named(tmp_path):
    (tmp_path / "run.json").write_text("{}")
    with pytest.raises(ValueError, match=r"run.json: is a file, not a directory; choose another --out"):
        train(ReachEnv(NUM_ENVS), tiny(iterations=1), tmp_path / "run.json", progress=False)


# --- on the real env ----------------------------------------------------------------------------------

SMALL = SimConfig(resolution=13)

JOB = TrainJob(
    contour="circle-small",
    sim=SMALL,
    eval_trials=1,
    train=TrainConfig(algo="es", num_envs=2, iterations=1, validation_trials=1, es=EsConfig(population=2)),
)
"""A tiny run of the default learner (es, observing the contour) on circle-small."""


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("real") / "circle-small"
    train_contour(JOB, run, progress=False)
    return run


@pytest.fixture
def real_copy(real_run, tmp_path):
    return shutil.copytree(real_run, tmp_path / "circle-small")


@pytest.mark.parametrize(
    "content, match",
    [
        ("[1, 2]", "options: expected a JSON object"),
        ('{"contour": 5}', "options: contour: a built-in name"),
        ('{"contour": "fls-circle", "allow_z": "yes"}', "options: allow_z: True or False"),
        (
            '{"contour": "fls-circle", "action_type": "jump"}',
            "options: action_type: one of 'discrete', 'continuous'",
        ),
        ('{"contour": "fls-circle", "sim_config": {"gravity_x": 1}}', "options: sim_config: unknown field"),
        (
            '{"contour": "fls-circle", "sim_config": {"resolution": 2}}',
            r"options: sim_config\.resolution: an integer in \[5, 100\]",
        ),
        (
            '{"contour": "fls-circle", "pinch_point": [1, 2, 3]}',
            r"options: pinch_point: a finite point \[x_mm, y_mm\]",
        ),
        ('{"contour": "fls-circle", "observe_pinch": true}', r"options: unknown field\(s\) observe_pinch"),
    ],
)
def test_a_garbage_options_file_is_named(tmp_path, content, match):
    (tmp_path / "options.json").write_text(content)
    with pytest.raises(ValueError, match=match) as error:
        load_options(tmp_path)
    assert str(error.value).startswith(f"{tmp_path / 'options.json'}: ")


def test_paths_of_the_wrong_kind_are_named(tmp_path):
    (tmp_path / "options.json").mkdir()
    with pytest.raises(ValueError, match=r"options.json: is a directory, not a file"):
        load_options(tmp_path)
    (tmp_path / "x.json").write_text("{}")
    with pytest.raises(ValueError, match=r"x.json: is a file, not a run directory"):
        load_options(tmp_path / "x.json")


def test_a_custom_contour_is_stored_in_the_run_not_its_path(tmp_path, monkeypatch):
    circle = load_contour("circle-small")
    spec = {"name": "my-circle", "closed": True, "points": (circle.points + [3.0, 0.0]).tolist()}
    (tmp_path / "my-circle.json").write_text(json.dumps(spec))
    monkeypatch.chdir(tmp_path)
    stored = PatternCutOptions(contour="my-circle.json").to_dict()["contour"]
    assert stored["name"] == "my-circle" and stored["sheet_size"] == [100.0, 100.0]
    assert np.allclose(stored["points"], circle.points + [3.0, 0.0])
    run = tmp_path / "run"
    run.mkdir()
    (run / "options.json").write_text(json.dumps({"contour": stored}))
    monkeypatch.chdir(run)  # elsewhere: the contour travels with the run
    loaded = load_options(run).contour
    assert isinstance(loaded, Contour) and loaded.name == "my-circle"
    assert np.array_equal(loaded.points, load_contour(tmp_path / "my-circle.json").points)


def test_a_run_directory_records_its_job_and_options(real_run):
    """``config.json`` is the job, its pinch point resolved (``--config`` runs it again); ``options.json``
    what the policy acts in; the summary names the learner."""
    config = json.loads((real_run / "config.json").read_text())
    options = load_options(real_run)
    assert config == to_plain(dataclasses.replace(JOB, pinch=options.pinch_point))
    assert config["train"]["algo"] == "es" and config["env"] == to_plain(EnvConfig())
    assert options.contour == "circle-small" and options.sim_config == SMALL and options.contour_features
    summary = json.loads((real_run / "summary.json").read_text())
    assert summary["algo"] == "es" and summary["status"] == "completed" and summary["iterations"] == 1
    assert read_checkpoint(real_run / BEST_CHECKPOINT)["algo"] == "es"


def test_resuming_with_other_settings_fails_before_touching_the_run(real_copy, capfd):
    before = {p.name: p.read_bytes() for p in real_copy.iterdir() if p.is_file()}
    changes = {
        "env.contour_features": (
            dataclasses.replace(JOB, env=EnvConfig(contour_features=False)), True, False,
        ),
        "seed": (dataclasses.replace(JOB, seed=5), 0, 5),
        # the validation episodes are fixed too: model selection compares each validation with the first
        "train.validation_trials": (
            dataclasses.replace(JOB, train=dataclasses.replace(JOB.train, validation_trials=2)), 1, 2,
        ),
    }  # fmt: skip
    for key, (job, theirs, ours) in changes.items():
        with pytest.raises(ValueError) as error:
            train_contour(job, real_copy, resume=real_copy, progress=False)
        assert str(error.value) == (
            f"{key}: the resumed run {real_copy} has {theirs!r} (its config.json), this job {ours!r}; a "
            "resumed run keeps its settings: drop the change, or start a new run"
        )
    # A run without its config.json: the policy itself must fit the env.
    (real_copy / "config.json").unlink()
    job = changes["env.contour_features"][0]
    with pytest.raises(ValueError) as error:
        train_contour(job, real_copy, resume=real_copy, progress=False)
    message = str(error.value)
    assert message.startswith(f"{real_copy / 'latest.pt'}: policy expects 47 observations, the env gives 40")
    assert "contour_features=True in the run, False here" in message
    assert {p.name: p.read_bytes() for p in real_copy.iterdir() if p.is_file()} == {
        name: data for name, data in before.items() if name != "config.json"
    }


def test_check_policy_run(real_copy, capfd):
    assert check_policy_run(real_copy, "circle-small").contour == "circle-small"
    check_policy_run(real_copy, PatternCutOptions(contour="circle-small", sim_config=SMALL))
    with pytest.raises(
        ValueError, match=r"circle-small: trained on contour 'circle-small', not on the requested 'fls"
    ):
        check_policy_run(real_copy, "fls-circle")
    moved = load_contour("circle-small")
    moved = Contour("circle-small", True, moved.points + [1.0, 0.0])
    with pytest.raises(ValueError, match=r"\(same name, other points\)"):
        check_policy_run(real_copy, moved)
    blind = PatternCutOptions(contour="circle-small", sim_config=SMALL, contour_features=False)
    with pytest.raises(ValueError, match=r"other settings than requested \(contour_features=True in the run"):
        check_policy_run(real_copy, blind)
    with pytest.raises(ValueError, match=r"resolution=13 in the run, 25 requested"):
        check_policy_run(real_copy, PatternCutOptions(contour="circle-small"))

    summary = json.loads((real_copy / "summary.json").read_text())
    (real_copy / "summary.json").write_text(json.dumps({**summary, "status": "interrupted"}))
    with pytest.raises(
        ValueError, match=r"training interrupted at iteration 1 \(summary.json\); set allow_partial=true"
    ):
        check_policy_run(real_copy, "circle-small")
    check_policy_run(real_copy, "circle-small", allow_partial=True)
    (real_copy / "summary.json").unlink()
    with pytest.raises(ValueError, match=r"no summary.json, its training never finished"):
        check_policy_run(real_copy, "circle-small")

    options = json.loads((real_copy / "options.json").read_text())
    (real_copy / "options.json").write_text(json.dumps({**options, "num_fiducials": 10}))
    with pytest.raises(ValueError, match=r"best.pt: policy expects 47 observations, .*options.json gives 41"):
        check_policy_run(real_copy, "circle-small", allow_partial=True)
    # A file of the run that is not a checkpoint: export names the run directory to give instead.
    err = cli_error(capfd, "export", str(real_copy / "config.json"))
    assert f"(such as {real_copy})" in err


def test_train_resume_needs_no_contour_and_refuses_a_conflicting_one(real_copy, capfd):
    conflicts = {
        ("--contour", "fls-circle"): "contour: the resumed run",
        ("--set", "env.contour_features=false"): "env.contour_features: the resumed run",
        ("--set", "env.allow_z=false"): "env.allow_z: the resumed run",
        ("--set", "train.validation_trials=16"): "train.validation_trials: the resumed run",
        ("--seed", "3"): "seed: the resumed run",
        ("--num-envs", "8"): "train.num_envs: the resumed run",
        ("--algo", "ppo"): "train.algo: the resumed run",
    }
    for args, start in conflicts.items():
        err = cli_error(capfd, "train", "--resume", str(real_copy), *args)
        assert (
            err.startswith(f"error: {start} {real_copy} has ") and "a resumed run keeps its settings" in err
        )
    err = cli_error(capfd, "train", "--iterations", "1")
    assert "contour: give the contour to train on (--contour)" in err

    one = json.loads((real_copy / "summary.json").read_text())["env_steps"]  # one whole cut in each env
    with pytest.raises(SystemExit) as exit_info:  # no --contour, --num-envs ...: the run knows them
        main.main(
            args=[
                "train",
                "--resume",
                str(real_copy),
                "--iterations",
                "2",
                "--no-progress",
                "--set",
                "plots=false",
            ],
            prog_name="warpcut",
        )
    assert exit_info.value.code == 0, capfd.readouterr().err
    summary = json.loads((real_copy / "summary.json").read_text())
    assert summary["iterations"] == 2 and summary["resumed_from"] == str(real_copy / LATEST_CHECKPOINT)
    assert summary["env_steps"] == 2 * one and [h["iteration"] for h in summary["history"]] == [1, 2]
    config = json.loads((real_copy / "config.json").read_text())
    assert config["train"]["num_envs"] == 2 and config["train"]["iterations"] == 2
