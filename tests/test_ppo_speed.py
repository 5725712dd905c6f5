"""agents.ppo.algorithm: the PPO speed-ups compute what rsl-rl computes."""

from __future__ import annotations

import types

import torch
from rsl_rl.storage import RolloutStorage
from tensordict import TensorDict

from agents.ppo.algorithm import mini_batches


def _filled_storage(num_envs: int = 6, steps: int = 4) -> RolloutStorage:
    obs = TensorDict({"policy": torch.zeros(num_envs, 5)}, batch_size=[num_envs])
    storage = RolloutStorage("rl", num_envs, steps, obs, (1,))
    g = torch.Generator().manual_seed(3)
    storage.observations["policy"].copy_(torch.randn(steps, num_envs, 5, generator=g))
    for name in ("actions", "values", "returns", "advantages", "actions_log_prob"):
        getattr(storage, name).copy_(torch.randn(steps, num_envs, 1, generator=g))
    storage.distribution_params = (torch.randn(steps, num_envs, 1, 7, generator=g),)
    return storage


def test_mini_batches_match_rsl_rl_bit_for_bit():
    storage = _filled_storage()
    torch.manual_seed(11)
    expected = list(storage.mini_batch_generator(3, 2))
    torch.manual_seed(11)
    got = list(types.MethodType(mini_batches, storage)(3, 2))
    assert len(got) == len(expected) == 6
    for a, b in zip(got, expected, strict=True):
        assert a.observations.batch_size == b.observations.batch_size
        assert torch.equal(a.observations["policy"], b.observations["policy"])
        for name in ("actions", "values", "advantages", "returns", "old_actions_log_prob"):
            assert torch.equal(getattr(a, name), getattr(b, name)), name
        pairs = zip(a.old_distribution_params, b.old_distribution_params, strict=True)
        assert all(torch.equal(p, q) for p, q in pairs)
    # Different draws give different batches: the comparison above can fail.
    torch.manual_seed(12)
    other = next(types.MethodType(mini_batches, storage)(3, 2))
    assert not torch.equal(other.observations["policy"], expected[0].observations["policy"])


def _spin_count_after(code: str, env: dict[str, str]) -> str:
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "GOMP_SPINCOUNT"} | env
    script = code + "; import os; print(os.environ.get('GOMP_SPINCOUNT', 'unset'))"
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_importing_agents_before_torch_shortens_openmp_spinning():
    from agents import OPENMP_SPIN_COUNT

    assert int(OPENMP_SPIN_COUNT) < 300_000  # libgomp's default
    assert _spin_count_after("import agents, torch", {}) == OPENMP_SPIN_COUNT
    assert _spin_count_after("import agents", {"GOMP_SPINCOUNT": "123"}) == "123"  # the user's value stands
    # once torch (and libgomp) is loaded the variable is no longer read: agents does not pretend to set it
    assert _spin_count_after("import torch, agents", {}) == "unset"
