"""Refusals name the real cause and what fixes it: the setting that sizes a batch too big for memory, the
OS limit behind a failed write, the size of a contour file too big to read."""

import pytest

from agents.cli import main
from warpcut.sim.memory import MEMORY_LIMIT_ENV


def refused(args, capfd) -> str:
    """The ``error: ...`` line ``args`` exits with, status 2, after its progress lines (no traceback)."""
    with pytest.raises(SystemExit) as exit_info:
        main.main(args=args, prog_name="warpcut")
    assert exit_info.value.code == 2
    err = capfd.readouterr().err
    lines = [line for line in err.strip().splitlines() if line.startswith("error")]
    assert len(lines) == 1 and err.strip().endswith(lines[0]) and "Traceback" not in err, err
    return lines[0]


# ------------------------------------------------------------------ batches too big for memory


@pytest.fixture
def tiny_memory(monkeypatch, tmp_path):
    """3 MB for a batch: ~25 envs of the default sheet; run in an empty folder."""
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "0.003")
    monkeypatch.chdir(tmp_path)


@pytest.mark.parametrize(
    ("args", "start", "advice"),
    [
        (["train", "--contour", "circle-small"], "train.num_envs: 256 envs", "set train.num_envs (train: "
         "--num-envs) to at most"),
        (["run", "--contour", "circle-small", "--set", "candidates=1"], "train.num_envs: 256 envs",
         "set train.num_envs"),
        (["evaluate", "--contours", "circle-small", "--methods", "none,rl", "--set", "candidates=1"],
         "train.num_envs: 256 envs", "set train.num_envs"),
        (["optimize", "--contour", "circle-small", "--estimator", "es", "--set", "candidates=1"],
         "es's batch (grad.es_population x grad.es_trials = 64 x 2): 128 envs",
         "lower grad.es_population (even) or grad.es_trials to at most"),
        (["optimize", "--contour", "circle-small", "--estimator", "tape", "--set", "candidates=1", "--set",
          "grad.trials=64"],
         "grad.trials: 64 envs", "set grad.trials to at most"),
        (["robustness", "--contour", "circle-small", "--study", "noise"],
         "the planner's batch (pinch candidates x segment orders): 60 envs",
         "give a trained run (--run LABEL=DIR)"),
    ],
)  # fmt: skip
def test_a_batch_too_big_for_memory_names_the_setting_that_sizes_it(args, start, advice, tiny_memory, capfd):
    error = refused([*args, "--device", "cpu"], capfd)
    assert error.startswith(f"error: {start} would need about "), error
    assert advice in error and "num_envs: " not in error.replace("train.num_envs: ", ""), error
    assert "candidates setting" not in error, error


def test_bench_names_the_option_of_the_batch_too_big(tiny_memory, monkeypatch, capfd):
    from warpcut import bench

    monkeypatch.setattr(bench, "start_times", lambda device: {})  # a fresh process each: seconds
    for args, start in (
        (["--batch-sizes", "64"], "--batch-sizes (B=64): 64 envs"),
        (["--batch-sizes", "1", "--rollout-envs", "1", "--train-envs", "64"], "--train-envs (B=64): 64 envs"),
    ):
        error = refused(["bench", "--device", "cpu", "--repeats", "1", *args], capfd)
        option = start.split()[0]
        assert error.startswith(f"error: {start} would need") and f"give {option} of at most" in error, error


def test_every_size_a_user_sets_is_checked_before_it_is_allocated(tmp_path, monkeypatch, capfd):
    """A billion envs, an actor of ten billion weights, a million generated contours: each is one line
    naming the setting, in seconds, before memory is taken (a list of a billion envs' contours is 8 GB)."""
    import time

    import gymnasium as gym

    import warpcut.gym  # noqa: F401 -- registers the env

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "8")
    start = time.perf_counter()
    with pytest.raises(ValueError, match="num_envs: 1000000000 envs would need about"):
        gym.make_vec("warpcut/PatternCut-v0", num_envs=10**9, vectorization_mode="vector_entry_point")
    train = ["train", "--contour", "circle-small"]
    for args, said in [
        ([*train, "--num-envs", "1000000000"], "train.num_envs: 1000000000 envs"),
        ([*train, "--set", "train.actor_hidden_dims=[100000,100000]"],
         "train.actor_hidden_dims: [100000, 100000] make an actor of at least 10,000,400,001 weights"),
        ([*train, "--algo", "ppo", "--set", "train.actor_hidden_dims=[99999,99999]"],
         "train.actor_hidden_dims: [99999, 99999]"),
        (["generalist", "--set", "train.actor_hidden_dims=[100000,100000]"], "train.actor_hidden_dims"),
        (["evaluate", "--contours", "gen-test-0:1000000"], "at most 10000 contours of a split"),
        (["generalist", "--set", "generated=1000000"], "generated: an integer in [0, 10000]"),
        (["plan", "--contour", "circle-small", "--candidates", "2000000000"], "the planner's batch"),
        (["evaluate", "--contours", "circle-small", "--set", "candidates=100000000"],
         "candidates: 100000001"),
        (["run", "--contour", "circle-small", "--policy", "fixed", "--set", "candidates=100000000"],
         "candidates: 100000001"),
        (["teachers", "--set", "candidates=100000000"], "candidates: 100000001"),
    ]:  # fmt: skip
        out = ["--out", str(tmp_path / "out")] if args[0] != "plan" else []
        error = refused([*args, "--device", "cpu", *out], capfd)
        assert said in error and not (tmp_path / "out").exists(), error
    assert time.perf_counter() - start < 60


# ------------------------------------------------------------------ the OS cause of a failed write


def test_a_kernel_cache_that_cannot_be_made_or_written_names_warp_cache_path(monkeypatch):
    import errno

    from warpcut.sim import _warp

    monkeypatch.setenv("WARP_CACHE_PATH", "/proc/warpcache")
    monkeypatch.setattr(_warp, "_initialised", False)
    monkeypatch.setattr(_warp, "_cuda_driver_loadable", lambda: True)  # wp.init() unwrapped
    for error, cause in (
        (
            FileNotFoundError(errno.ENOENT, "No such file or directory", "/proc/warpcache"),
            "make it a writable",
        ),
        (OSError(errno.EFBIG, "File too large"), "the file-size limit of this shell (ulimit -f)"),
    ):
        monkeypatch.setattr(_warp.wp, "init", lambda error=error: (_ for _ in ()).throw(error))
        with pytest.raises(_warp.KernelCacheError, match="WARP_CACHE_PATH=/proc/warpcache") as refusal:
            _warp.init()
        assert cause in str(refusal.value) and "\n" not in str(refusal.value)
    monkeypatch.setattr(_warp.wp, "load_module", lambda *a, **k: (_ for _ in ()).throw(error))
    with pytest.raises(_warp.KernelCacheError, match=r"ulimit -f\) is") as refusal:  # not "may be corrupt"
        _warp.load_module(type("Module", (), {"name": "m"})(), "cpu")
    assert "corrupt" not in str(refusal.value)


def test_a_temporary_folder_refused_under_a_file_size_limit_names_the_limit(monkeypatch, capfd):
    import errno

    from agents.cli import contours
    from warpcut import limits

    def fails(**options):  # what Python's tempfile raises (torch calls it on import) under ulimit -f 0
        raise FileNotFoundError(errno.ENOENT, "No usable temporary directory found in ['/tmp']")

    monkeypatch.setattr(contours.command, "callback", fails)
    monkeypatch.setattr(limits, "file_size_limit", lambda: 0)
    error = refused(["contours"], capfd)
    assert (
        "No usable temporary directory" in error and "file-size limit of this shell (ulimit -f) is 0" in error
    )


@pytest.mark.skipif(not __import__("os").path.isdir("/proc/1"), reason="no /proc")
def test_an_output_folder_where_files_cannot_be_made_says_so():
    import click

    from agents.cli.outputs import check_outputs

    with pytest.raises(click.BadParameter, match=r"/proc/1: files cannot be created there"):
        check_outputs({"--out": __import__("pathlib").Path("/proc/1")})


def test_a_first_best_checkpoint_not_written_says_there_was_none(monkeypatch, tmp_path):
    import errno
    from types import SimpleNamespace

    import torch

    from agents import runner as runner_module
    from warpcut.io import WriteFailed

    def full(path, data):
        raise WriteFailed(path, OSError(errno.ENOSPC, "No space left on device"))

    monkeypatch.setattr(runner_module, "write_atomic", full)
    runner = SimpleNamespace(
        alg=SimpleNamespace(get_policy=lambda: torch.nn.Linear(1, 1)),
        _selection_score=lambda errors: (1.0, 1.0),
        _guarded_ok=lambda errors: True,
        validation=[],
        logger=SimpleNamespace(writer=None, log_dir=str(tmp_path)),
        iterations_done=0,
        best_error=None,
        best_score=None,
        best_iterations=None,
        _state_bytes=lambda: b"state",
    )
    with pytest.raises(ValueError, match=r"best\.pt: not written, the disk is full; none was saved before"):
        runner_module.Runner.validate(runner, lambda actor: 1.0)
    (tmp_path / "best.pt").write_bytes(b"earlier")
    with pytest.raises(ValueError, match=r"the previous best\.pt is intact"):
        runner_module.Runner.validate(runner, lambda actor: 1.0)


def test_a_recording_cut_short_by_the_file_size_limit_names_it(monkeypatch, tmp_path):
    from warpcut import limits
    from warpcut.viz import process
    from warpcut.viz.process import RecordingError, place_file

    tmp, path = tmp_path / ".r.rrd.tmp", tmp_path / "r.rrd"
    tmp.write_bytes(b"\0" * 4096)  # no rerun footer: cut short at the limit
    monkeypatch.setattr(limits, "file_size_limit", lambda: 4096)
    with pytest.raises(RecordingError) as refusal:
        place_file(tmp, path, keep=True)
    message = str(refusal.value)
    assert "ulimit -f) is 4096 bytes" in message and "disk full" not in message, message
    assert "the file holds what was written, truncated" in message and path.stat().st_size == 4096
    monkeypatch.delenv("WARPCUT_VERBOSE", raising=False)
    monkeypatch.delenv("RUST_LOG", raising=False)
    assert process._child_environment()["RUST_LOG"] == "off"  # rerun's own ERROR/WARN lines: not printed


# ------------------------------------------------------------------ contour files too big to read


@pytest.mark.parametrize("suffix", [".json", ".svg"])
def test_a_contour_file_too_big_is_refused_before_it_is_read(suffix, tmp_path):
    from warpcut.contours import ContourError, load_contour
    from warpcut.contours.loaders import MAX_FILE_BYTES

    path = tmp_path / f"big{suffix}"
    with open(path, "wb") as f:
        f.truncate(4 * 2**30)  # sparse: 4 GiB that takes no room
    with pytest.raises(ContourError, match=r"4,096 MiB, larger than the 64 MiB a contour file may be"):
        load_contour(path)
    assert MAX_FILE_BYTES == 64 * 2**20
