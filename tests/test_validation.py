"""Every public config and constructor checks what it is given where it comes in (:mod:`warpcut.validation`):
a wrong type or value is a one-line ``ValueError`` naming ``Class.field``, never a run with a value taken for
another (a bool for a number, 0 envs for "the default") nor an error from deep inside."""

from __future__ import annotations

import dataclasses
import math
import os
import re
import subprocess
import sys
import types
import typing
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import event, given
from hypothesis import strategies as st

from envs import PatternCutEnv, PatternCutVecEnv
from envs.options import EnvConfig, PatternCutOptions
from warpcut import CuttingTask, SheetGrid, SimConfig, Simulator
from warpcut.contours import Contour, load_contour

ROOT = Path(__file__).resolve().parents[1]
CONTOUR = load_contour("circle-small")
SMALL = SimConfig(resolution=5, settle_updates=5)


def refused(build, where: str) -> str:
    """The message of the ValueError ``build()`` raises: one line, starting with ``where: ``."""
    with pytest.raises(ValueError) as error:
        build()
    message = str(error.value)
    assert message.startswith(f"{where}: ") and "\n" not in message, message
    return message


# ------------------------------------------------------------------ what a hostile user found
@pytest.mark.parametrize("num_envs", [0, -1, 2.0, True, "2"])
def test_a_batch_of_no_envs_is_refused_not_run_as_one(num_envs):
    message = refused(
        lambda: CuttingTask(SMALL, CONTOUR, num_envs=num_envs, device="cpu"), "CuttingTask.num_envs"
    )
    assert message.endswith(f"an integer >= 1, or None for one per contour (got {num_envs!r})")
    refused(lambda: Simulator(SMALL, num_envs, device="cpu"), "Simulator.num_envs")
    refused(
        lambda: PatternCutVecEnv(num_envs, contour="circle-small", device="cpu"), "PatternCutVecEnv.num_envs"
    )


@pytest.mark.parametrize(
    "field, value",
    [("noise_std", True), ("gravity", False), ("width_mm", True), ("damping", [True, 0.9]), ("sweeps", True)],
)
def test_a_bool_is_not_a_number(field, value):
    assert refused(lambda: SimConfig(**{field: value}), f"SimConfig.{field}").endswith(f"(got {value!r})")


def test_wrong_values_name_the_field_and_what_it_takes():
    message = refused(lambda: SimConfig(gravity="high"), "SimConfig.gravity")
    assert message == (
        "SimConfig.gravity: a number in [0, 100000] mm/s^2, or a list of one per env (downward; default 521) "
        "(got 'high')"
    )
    message = refused(lambda: SimConfig(resolution=25.5), "SimConfig.resolution")
    assert message == (
        "SimConfig.resolution: an integer in [5, 100], or a pair (nx, ny) of them (the paper: 25) (got 25.5)"
    )
    message = refused(lambda: SimConfig(cut_radius_mm="wide"), "SimConfig.cut_radius_mm")
    assert message == "SimConfig.cut_radius_mm: a number > 0 mm, or None for one grid spacing (got 'wide')"


def test_numpy_scalars_are_numbers_and_stored_as_python_ones():
    config = SimConfig(
        resolution=np.int64(9), sweeps=np.int32(7), gravity=np.float32(500.0), width_mm=np.float64(90.0)
    )
    assert (config.resolution, config.nx, config.sweeps) == (9, 9, 7) and type(config.resolution) is int
    assert type(config.gravity) is float and type(config.width_mm) is float
    assert SimConfig(resolution=[np.int64(9), 11]).resolution == (9, 11)
    assert SimConfig(noise_std=np.array([0.01, 0.02])).per_env("noise_std", 2).tolist() == pytest.approx(
        [0.01, 0.02]
    )
    assert SheetGrid(np.int64(5), 5, 100.0, 100.0).nx == 5
    assert CuttingTask(SMALL, CONTOUR, num_envs=np.int64(2), seed=np.int64(3), device="cpu").num_envs == 2
    assert PatternCutOptions(num_fiducials=np.int64(4), max_episode_steps=np.int32(5)).num_fiducials == 4


def test_a_config_changed_after_it_was_made_is_checked_again():
    config = SimConfig(resolution=5)
    config.noise_std = True  # a dataclass's fields may be assigned; the task checks them all again
    refused(lambda: CuttingTask(config, CONTOUR, device="cpu"), "SimConfig.noise_std")
    options = PatternCutOptions(contour="circle-small", sim_config=SMALL, device="cpu")
    options.num_fiducials = 2.0
    refused(lambda: PatternCutVecEnv(1, options), "PatternCutOptions.num_fiducials")


def test_the_envs_name_their_options_and_gym_make_too():
    refused(lambda: PatternCutEnv(noise_std=True, device="cpu"), "PatternCutOptions.noise_std")
    refused(
        lambda: gym.make("warpcut/PatternCut-v0", contour="circle-small", num_fiducials=2.0),
        "PatternCutOptions.num_fiducials",
    )
    refused(lambda: PatternCutVecEnv(2, render_envs=0, device="cpu"), "PatternCutVecEnv.render_envs")


def test_a_json_options_file_names_the_field_as_the_file_has_it():
    message = str(
        pytest.raises(ValueError, PatternCutOptions.from_dict, {"sim_config": {"resolution": 2.5}}).value
    )
    assert message.startswith("options: sim_config.resolution: an integer in [5, 100]"), message
    message = str(pytest.raises(ValueError, PatternCutOptions.from_dict, {"allow_z": "yes"}).value)
    assert message == "options: allow_z: True or False (got 'yes')"


# ------------------------------------------------------------------ every field of every public config
def hint_kind(hint) -> str | None:
    """What a field's type hint says it takes (None: a field with its own wrong values, :data:`SPECIAL`)."""
    args = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
    optional = type(None) in args
    core = tuple(a for a in args if a is not type(None))
    kinds = {(bool,): "flag", (int,): "count", (float,): "number", (str,): "text"}
    kind = kinds.get(core)
    if kind is None and float in core and int in core and np.ndarray in core:
        kind = "per_env"
    if kind is None and len(core) == 1 and dataclasses.is_dataclass(core[0]):
        kind = "section"
    return None if kind is None else kind + ("?" if optional else "")


WRONG = {
    "flag": [1, 0, "true", None],
    "count": [True, 2.5, 2.0, "3", math.nan, None],
    "number": [True, "1.0", math.nan, math.inf, -math.inf, None],
    "text": [1, True, None],
    "per_env": [True, "0.1", [0.1, "x"], [True, 0.5], math.nan, [math.nan], math.inf, [[0.1]], [], None],
    "section": [5, "x"],
}
"""Values of the wrong type for each kind of field (``kind?``, an optional field: these but None)."""

SPECIAL = {
    "resolution": [25.5, True, "25", (5,), (5, 5.0), [5, True], 4, 101],
    "springs": ["structural", ("shear",), ("structural", 1), None],
    "contour": [123, None, [], [""], [5]],
    "pinch_point": [[1, 2, 3], "ab", [math.nan, 1.0], [True, 1.0], 5],
    "segments": ["abc", 5],
    "sim_config": [5, "x", None],
    "randomize": ["gravity", ["wind"], [1], None],
    "randomize_ranges": [5, {"gravity": 5}, {"gravity": [0, "x"]}, {"gravity": [True, 1]}],
    "Contour.name": [1, "", None],
    "Contour.points": [
        [[0, 0], [1, 1]],
        np.zeros((3, 3)),
        np.array([[0.0, 0.0], [np.nan, 1.0]]),
        np.zeros((1, 2)),
    ],
    "Contour.sheet_size": [(100.0,), (True, 100.0), (100.0, math.inf), (0, 100), "ab", None],
}
"""Fields whose hint says too little: their own wrong values (by name, or ``Class.name``)."""


def wrong_values(cls: type, name: str, hint) -> list:
    special = SPECIAL.get(f"{cls.__name__}.{name}", SPECIAL.get(name))
    if special is not None:
        return special
    kind = hint_kind(hint)
    assert kind is not None, f"{cls.__name__}.{name}: add its wrong values to SPECIAL"
    return [v for v in WRONG[kind.rstrip("?")] if not (kind.endswith("?") and v is None)]


DATACLASS_BASES = {
    SimConfig: {},
    SheetGrid: {"nx": 5, "ny": 5, "width_mm": 100.0, "height_mm": 100.0},
    EnvConfig: {},
    PatternCutOptions: {},
    Contour: {"name": "c", "closed": True, "points": CONTOUR.points},
}
"""The public config dataclasses, and the fields each needs to be made."""

FIELD_CASES = [
    (cls, f.name, value)
    for cls, base in DATACLASS_BASES.items()
    for f in dataclasses.fields(cls)
    if f.init
    for value in wrong_values(cls, f.name, typing.get_type_hints(cls)[f.name])
]


@pytest.mark.parametrize(
    "cls, field, value", FIELD_CASES, ids=[f"{c.__name__}.{f}={v!r:.20}" for c, f, v in FIELD_CASES]
)
def test_every_config_field_refuses_a_wrong_value_by_name(cls, field, value):
    refused(lambda: cls(**{**DATACLASS_BASES[cls], field: value}), f"{cls.__name__}.{field}")


CONSTRUCTOR_CASES = {
    "config": [None, {"resolution": 5}, "SimConfig()"],
    "contours": [None, "circle-small", [], [CONTOUR, "x"]],
    "num_envs": [0, 2.0, True, "1"],
    "seed": [-1, 1.5, True, "0", None, 2_147_483_647],  # the last: seed 0's noise again (modulo a prime)
    "device": [0, True],
    "backend": ["magic", 1, None],
    "threads": [0, 2.0, True],
    "trace_path": [1, "yes", None],
    "capture": [1, "yes"],
}
"""Wrong arguments of the constructors that are not dataclasses."""


@pytest.mark.parametrize("arg", sorted(CONSTRUCTOR_CASES))
def test_the_task_and_simulator_refuse_a_wrong_argument_by_name(arg):
    task = {"config": SMALL, "contours": CONTOUR, "num_envs": 1, "device": "cpu"}
    sim = {"config": SMALL, "num_envs": 1, "device": "cpu"}
    for value in CONSTRUCTOR_CASES[arg]:
        if arg != "capture":
            refused(lambda v=value: CuttingTask(**{**task, arg: v}), f"CuttingTask.{arg}")
        if arg not in ("contours", "trace_path"):
            refused(lambda v=value: Simulator(**{**sim, arg: v}), f"Simulator.{arg}")


# ------------------------------------------------------------------ fuzzing: a valid object or one line
def anything() -> st.SearchStrategy:
    """Values of every type a config field might be given, sane and not."""
    scalars = st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-3, 300),
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from(
            [np.int64(7), np.float32(0.5), np.bool_(True), "corners", "rows", "", "x", "structural"]
        ),
    )
    return st.one_of(scalars, st.lists(scalars, max_size=3), st.lists(scalars, max_size=3).map(tuple))


@pytest.mark.parametrize("cls", list(DATACLASS_BASES), ids=lambda c: c.__name__)
@given(data=st.data())
def test_any_value_of_any_field_makes_a_config_or_one_line_naming_the_field(cls, data):
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    chosen = data.draw(st.lists(st.sampled_from(names), min_size=1, max_size=3, unique=True))
    given_values = {name: data.draw(anything(), label=name) for name in chosen}
    try:
        made = cls(**{**DATACLASS_BASES[cls], **given_values})
    except ValueError as error:  # never a TypeError, an AttributeError...
        where = one_line_naming(error, cls.__name__)
        assert where.split(".")[1] in given_values, str(error)
        event(f"refused {where}")
        return
    if isinstance(made, SimConfig):
        try:
            made.validated()  # the fields that depend on each other: one of them is named
        except ValueError as error:
            event(f"refused {one_line_naming(error, 'SimConfig')}")
            return
    event("made")


def one_line_naming(error: ValueError, owner: str) -> str:
    """The ``Class.field`` an error names: one line, ``owner``'s field."""
    message = str(error)
    where = message.split(": ", 1)[0]
    assert "\n" not in message and where.startswith(f"{owner}.") and ": " in message, message
    return where


# ------------------------------------------------------------------ errors that name the real cause
def test_a_contour_path_that_is_not_a_regular_file_says_what_it_is(tmp_path):
    fifo = tmp_path / "shape.json"
    os.mkfifo(fifo)  # reading it would block: it is never opened
    with pytest.raises(
        ValueError, match=r"shape\.json' is not a regular file \(a FIFO\); give a built-in name"
    ):
        load_contour(fifo)
    zero = tmp_path / "zero.json"
    zero.symlink_to("/dev/zero")  # reading it would never end
    with pytest.raises(ValueError, match=r"zero\.json' is not a regular file \(a character device\)"):
        load_contour(zero)
    with pytest.raises(ValueError, match=r"and no such file"):
        load_contour(tmp_path / "missing.json")


CACHE_PROBE = """
import errno, os, sys
if sys.argv[1] == "read-only":  # what a read-only folder gives, for a user who is not root
    real = os.makedirs
    def makedirs(path, *args, **kwargs):
        if str(path).startswith(os.environ["WARP_CACHE_PATH"]):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real(path, *args, **kwargs)
    os.makedirs = makedirs
try:
    from warpcut.sim.devices import resolve_device

    resolve_device("cpu")
except ValueError as error:
    print(type(error).__name__, error)
"""


@pytest.mark.parametrize("case", ["below-a-file", "read-only"])
def test_an_unwritable_kernel_cache_is_named_with_the_fix(tmp_path, case):
    blocker = tmp_path / "file"
    blocker.write_text("")
    cache = blocker / "cache" if case == "below-a-file" else tmp_path / "cache"
    env = {**os.environ, "WARP_CACHE_PATH": str(cache)}
    env.pop("WARPCUT_VERBOSE", None)
    done = subprocess.run(
        [sys.executable, "-c", CACHE_PROBE, case],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=120,
    )
    line = done.stdout.strip()
    assert done.returncode == 0 and "\n" not in line, done.stdout + done.stderr
    assert line.startswith("KernelCacheError Warp kernels: cannot create or write the kernel cache, ")
    assert f"WARP_CACHE_PATH={cache}" in line and "point WARP_CACHE_PATH at one" in line, line


def test_the_memory_limit_names_what_simulate_controls(monkeypatch):
    from agents.baselines import search_fixed_pinch

    monkeypatch.setenv("WARPCUT_MEMORY_LIMIT_GB", "0.002")
    with pytest.raises(ValueError) as error:
        search_fixed_pinch(CONTOUR, SimConfig(resolution=25), device="cpu")
    message = str(error.value)
    assert re.match(
        r"fixed's pinch search \(one env per candidate pinch point\): \d+ envs would need", message
    )
    assert "give fixed a pinch point (simulate --pinch X,Y)" in message and "num_envs" not in message


def test_a_batch_whose_every_env_is_too_big_says_so_and_not_at_most_0(monkeypatch):
    from agents.baselines import search_fixed_pinch

    monkeypatch.setenv("WARPCUT_MEMORY_LIMIT_GB", "0.000001")
    with pytest.raises(ValueError) as error:
        search_fixed_pinch(CONTOUR, SimConfig(resolution=25), device="cpu")
    message = str(error.value)
    assert "even one is too big: its sheet has 625 vertices" in message and "at most 0" not in message


def test_agent_configs_and_jobs_check_each_field_as_they_are_made():
    """The learners' configs, the optimiser's and every job refuse a field of the wrong kind at
    construction, in one line naming ``Class.field``; GradConfig's own checks name its own keys."""
    from agents.config import TrainConfig
    from agents.es.config import EsConfig
    from agents.jobs import EvaluateJob, OptimizeJob, RobustnessJob, RunJob, SimulateJob, TrainJob
    from agents.plan_optimizer.config import GradConfig

    for make, message in [
        (lambda: TrainConfig(num_envs=True), "TrainConfig.num_envs: an integer in [1, 2147483647]"),
        (lambda: TrainConfig(iterations=1.5), "TrainConfig.iterations: an integer in [1, 2147483647]"),
        (lambda: TrainConfig(iterations=10**20), "TrainConfig.iterations: an integer in [1, 2147483647]"),
        (lambda: TrainConfig(activation="nope"), "TrainConfig.activation: one of 'elu'"),
        (lambda: TrainConfig(algo="x"), "TrainConfig.algo: choose one of gps, es, ppo, apg"),
        (lambda: TrainConfig(actor_hidden_dims=[]), "TrainConfig.actor_hidden_dims: a non-empty list"),
        (lambda: TrainConfig(torch_device="gpu"), "TrainConfig.torch_device: a torch device"),
        (lambda: TrainConfig(obs_normalization="no"), "TrainConfig.obs_normalization: True or False"),
        (lambda: EsConfig(sigma=-1.0), "train.es.sigma: must be a finite number > 0"),
        (lambda: TrainJob(seed=True), "TrainJob.seed: an integer in [0, 2147418111]"),
        (lambda: TrainJob(contour=5), "TrainJob.contour: a built-in name"),
        (lambda: TrainJob(train="es"), "TrainJob.train: a TrainConfig"),
        (lambda: TrainJob(eval_trials=0), "TrainJob.eval_trials: must be an integer >= 1"),
        (lambda: GradConfig(iterations=2.0), "GradConfig.iterations: an integer (got 2.0)"),
        (lambda: OptimizeJob(grad=GradConfig(window=2.5)), "GradConfig.window: an integer >= 1"),
        (lambda: GradConfig(optimize_pinch="yes"), "GradConfig.optimize_pinch: True or False"),
        (lambda: RunJob(candidates=2.0), "RunJob.candidates: must be an integer >= 1"),
        (lambda: RunJob(trials=math.nan), "RunJob.trials: must be an integer >= 1"),
        (lambda: RunJob(policy="x"), "RunJob.policy: choose one of fixed, analytic, rl"),
        (lambda: RunJob(seed=2**31), "RunJob.seed: an integer in [0, 2147418111] (got 2147483648)"),
        (lambda: EvaluateJob(methods="none"), "EvaluateJob.methods: a list of method names"),
        (lambda: EvaluateJob(sim={}), "EvaluateJob.sim: a SimConfig"),
        (lambda: RobustnessJob(values=[math.nan]), "RobustnessJob.values: a list of finite numbers"),
        (lambda: SimulateJob(trials=0), "SimulateJob.trials: must be an integer >= 1"),
    ]:
        with pytest.raises(ValueError) as error:
            make()
        assert str(error.value).startswith(message), str(error.value)
    grad = GradConfig()
    object.__setattr__(grad, "validation_trials", -1)  # past the constructor: validated() checks it again
    with pytest.raises(ValueError, match=r"^GradConfig.validation_trials: an integer >= 0"):
        grad.validated()


def test_cli_refuses_bad_train_settings_before_claiming_the_run(tmp_path, monkeypatch):
    """Settings that used to fail deep inside training (torch, rsl-rl, the final evaluation) are refused
    before the run directory is made, in one line naming the key as typed."""
    from tests.cli_runner import invoke

    monkeypatch.chdir(tmp_path)
    out = tmp_path / "c1"
    for setting, message in [
        ("train.actor_hidden_dims=[]", "--set: train.actor_hidden_dims: a non-empty list"),
        ("train.torch_device=gpu", "--set: train.torch_device: a torch device"),
        ("train.activation=nope", "--set: train.activation: one of"),
        ("eval_trials=0", "--set: eval_trials: must be an integer >= 1"),
        ("train.obs_normalization='no'", "--set: train.obs_normalization: expected true or false"),
    ]:
        code, stdout, stderr = invoke(
            ["train", "--contour", "circle-small", "--set", setting, "--out", str(out)]
        )
        assert code == 2 and message in stderr and len(stderr.strip().splitlines()) == 1, stderr
        assert not stdout
    assert not out.exists() and not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"allow_infeasible_pinch": "no"}, "CuttingTask.allow_infeasible_pinch"),
        ({"allow_infeasible_pinch": 1}, "CuttingTask.allow_infeasible_pinch"),
        ({"arm": "x"}, "CuttingTask.arm"),
        ({"segments": [[[1, 2]]]}, "CuttingTask.segments[0]"),
        ({"segments": "abc"}, "CuttingTask.segments"),
        ({"segments": [[np.array([[0.0, 0.0], [np.nan, 1.0]])]]}, "CuttingTask.segments[0]"),
        ({"pinch_points": "36,60"}, "CuttingTask.pinch_points"),
        ({"pinch_points": np.array([True, False])}, "CuttingTask.pinch_points"),
        ({"pinch_points": np.zeros((3, 2))}, "CuttingTask.pinch_points"),
        ({"device": "gpu"}, "CuttingTask.device"),
    ],
)
def test_the_task_names_a_bad_grasp_cut_or_device(kwargs, field):
    """The task's grasp, cut and device arguments: one line naming ``CuttingTask.FIELD``, never a NumPy
    conversion error from inside (a text as coordinates, bools as numbers, a ragged or NaN polyline)."""
    from warpcut import load_contour

    with pytest.raises(ValueError, match=re.escape(field) + ": ") as error:
        CuttingTask(SimConfig(resolution=13), load_contour("circle-small"), num_envs=1, **kwargs)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"randomize": ("gravity",), "randomize_ranges": {"gravity": [float("nan"), 1.0]}},
        {"randomize": ("gravity",), "randomize_ranges": {"gravity": [2.0, 1.0]}},
        {"segments": [[1, 2]]},
        {"segments": [[[0.0, 0.0], [float("nan"), 1.0]]]},
    ],
)
def test_the_env_options_name_bad_ranges_and_cuts_when_made(kwargs):
    """Ranges and cut polylines are checked when the options are made, naming the class and field, not
    later inside gym.make."""
    from envs.options import PatternCutOptions

    with pytest.raises(ValueError, match=r"PatternCutOptions\.(randomize_ranges|segments): "):
        PatternCutOptions(**kwargs)
