"""The generalist: one tensioning policy for every contour, played zero-shot on contours it never saw
(:func:`generalist_result`, the ``generalist`` method of ``evaluate``, ``run``, ``simulate`` and
``robustness``). :func:`agents.pipelines.generalist.train_generalist` (``warpcut generalist``) trains one; the
one warpcut ships is :data:`SHIPPED` (``"generalist"``).

A generalist's directory holds its policy (``best.pt``, or the run's checkpoints) and ``generalist.json``:
what it observes and how it acts (``env``: :class:`~envs.options.EnvConfig`, with its look-ahead), the
physics it was trained on (``sim``), its training and validation contours, and the command that trained it;
and, where it lists them (:data:`MEMBERS`), its members: policies trained alike from other seeds, each in a
folder of its own. It plays each contour in the planned segments, with the policy, at the plan's pinch
candidate and with the gain on its moves where it validates best, and holds still where that choice cuts no
better than holding still on fresh episodes (:func:`guarded_result`: ``run`` and ``evaluate``); what it
observes lets it tension any of them (:mod:`envs.observations`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from agents.config import GAIN_SHORTLIST, GENERALIST_FINALISTS, GENERALIST_GAINS, check_gains
from envs.options import EnvConfig, PatternCutOptions
from warpcut.contours import Contour
from warpcut.io import read_json
from warpcut.sim.config import SimConfig

if TYPE_CHECKING:
    import torch

    from agents.evaluation import MethodResult
    from warpcut.planning import ArmModel
    from warpcut.task import StepCallback

GENERALIST_FILE = "generalist.json"
"""A generalist's settings in its directory: the env it acts in (``env``, ``sim``) and how it was trained."""

SHIPPED = "generalist"
"""The name that plays the generalist warpcut ships (:data:`SHIPPED_DIR`)."""

SHIPPED_DIR = Path(__file__).resolve().parent / "data" / "generalist"
"""The shipped generalist: its policy (``best.pt``) and ``generalist.json``."""

FORMAT = 1
"""The layout of ``generalist.json``."""

MEMBERS = "members"
"""The key in ``generalist.json`` that lists its other members: folders in its directory, each a
generalist's directory of its own (``generalist.json`` and ``best.pt``) with the same ``env``
(:attr:`Generalist.members`; ``scripts/ship_generalist.py RUN --member RUN2``)."""

POLICY_FIELDS = ("actor_hidden_dims", "activation", "obs_normalization")
"""The :class:`~agents.config.TrainConfig` fields that shape a generalist's network (``policy`` in
``generalist.json``, with :data:`ES_FIELDS`): what fine-tuning from it takes."""

ES_FIELDS = ("feedback", "scheduled", "sigma", "learning_rate")
"""es's settings fine-tuning takes from the generalist (``policy`` in ``generalist.json``): its network
(the feedback path, scheduled gains) and the MLP's perturbation and step. Per-contour es's own σ (0.005)
suits an MLP that starts at "hold still"; from a generalist, whose MLP carries the scheduled gains, its
steps are too small to move it: with the generalist's (0.01, 0.003) fine-tuning reached the per-contour
level on 3 of 4 contours, against 2 of 4 (``scripts/fine_tuning.py``; docs/results.md)."""

SCORE_KEYS = ("error_vertices", "error_mm2", "separated", "dropped_fraction")


def generalist_dir(source: str | Path | None) -> Path:
    """The directory of the generalist ``source`` names: ``"generalist"`` or None, the shipped one; else a
    run directory of ``warpcut generalist`` (or a copy of the shipped one's files)."""
    if source is None or str(source) == SHIPPED:
        return SHIPPED_DIR
    path = Path(source)
    if not (path / GENERALIST_FILE).is_file():
        what = "no such directory" if not path.exists() else f"holds no {GENERALIST_FILE}"
        raise ValueError(
            f"generalist: {path}: {what}; give a run directory of 'warpcut generalist', or 'generalist' for "
            "the shipped one"
        )
    if not any(path.glob("*.pt")):
        raise ValueError(
            f"generalist: {path}: holds {GENERALIST_FILE} but no policy (best.pt); restore it, or train one "
            "(warpcut generalist)"
        )
    return path


def generalist_settings(source: str | Path | None) -> dict:
    """``generalist.json`` of the generalist ``source`` (:func:`generalist_dir`)."""
    return _read_settings(generalist_dir(source))


def _read_settings(directory: Path) -> dict:
    """``generalist.json`` in ``directory``, its env and physics checked."""
    path = directory / GENERALIST_FILE
    try:
        data = read_json(path)
        EnvConfig(**data["env"])
        SimConfig.from_dict(data["sim"], "sim")
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"generalist: {path} cannot be read ({exc}); restore it, or train again") from None
    return data


@dataclass(frozen=True)
class Generalist:
    """A generalist read once (:func:`load_generalist`): what :func:`generalist_result` plays."""

    settings: dict
    """Its ``generalist.json``."""
    actor: torch.nn.Module
    """Its policy (:func:`agents.policies.load_policy`), on the CPU, in eval mode: what fine-tuning starts
    from and what plays at a given pinch point."""
    members: tuple[torch.nn.Module, ...] = ()
    """The policies of its other members (:data:`MEMBERS`), loaded as :attr:`actor` is: policies trained the
    same way from other seeds, which observe and act as it does; :func:`guarded_result` plays, contour by
    contour, the one that validates best."""

    @property
    def actors(self) -> tuple[torch.nn.Module, ...]:
        """Its policy, then its members' (the index a :class:`Guarded` reports)."""
        return (self.actor, *self.members)


def load_generalist(source: str | Path | None) -> Generalist:
    """The generalist ``source`` names (:func:`generalist_dir`): its settings, its policy and its members'
    (:data:`MEMBERS`), each checked to observe and act as its settings say.

    Raises:
        ValueError: No such generalist, or its settings or policy cannot be read or do not fit each other;
            the message names the file and the fix.
    """
    from agents.policies import load_policy

    directory = generalist_dir(source)
    settings = _read_settings(directory)
    env = EnvConfig(**settings["env"])
    folders = [directory, *_members(directory, settings)]
    actor, *members = [load_policy(d, env, GENERALIST_FILE, "restore it, or train again") for d in folders]
    return Generalist(settings, actor, tuple(members))


def _members(directory: Path, settings: dict) -> list[Path]:
    """The folders of the members ``settings`` (the ``generalist.json`` in ``directory``) lists, each
    checked to be a generalist's directory in ``directory`` that observes and acts as it does."""
    names = settings.get(MEMBERS, [])
    if not isinstance(names, list):
        raise ValueError(
            f"generalist: {directory / GENERALIST_FILE}: {MEMBERS} must be a list of member folders in "
            f"{directory} (got {names!r}); restore it, or ship it again (scripts/ship_generalist.py)"
        )
    folders = []
    for name in names:
        where = f"generalist: {directory / GENERALIST_FILE}: member {name!r}"
        if not isinstance(name, str) or not name or Path(name).is_absolute() or ".." in Path(name).parts:
            raise ValueError(f"{where}: name a folder inside {directory}; restore it, or ship it again")
        try:
            own = _read_settings(generalist_dir(directory / name))
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        differ = env_differences(settings["env"], own["env"])
        if differ:
            raise ValueError(
                f"{where}: observes or acts otherwise than the generalist ({', '.join(differ)} differ); its "
                "members must be trained with the same env settings"
            )
        folders.append(directory / name)
    return folders


def env_differences(env: dict, other: dict) -> list[str]:
    """The fields in which two generalists' ``env`` settings differ (none: a member may join the other)."""
    return sorted(k for k in {*env, *other} if env.get(k) != other.get(k))


def generalist_options(
    generalist: Generalist,
    contours: Sequence[Contour],
    pinches: Sequence[np.ndarray],
    segments: Sequence[Sequence[np.ndarray]] | None,
    config: SimConfig,
    trials: int = 1,
    device: str | None = None,
    **overrides,
) -> PatternCutOptions:
    """The options of a batch that plays ``generalist`` on ``contours`` (``trials`` envs each, contour by
    contour, at ``pinches``, cutting ``segments``), with the observations and actions it was trained with and
    ``config``'s physics."""
    env = {**generalist.settings["env"], "randomize": [], "randomize_ranges": None}  # on the physics given
    per_env = [k for k in range(len(contours)) for _ in range(trials)]
    listed = None if segments is None else [[np.asarray(p).tolist() for p in cut] for cut in segments]
    cut = None if listed is None else [listed[k] for k in per_env]  # a contour's envs share its cut
    return PatternCutOptions(
        contour=[contours[k] for k in per_env],
        pinch_point=np.array([np.asarray(pinches[k], dtype=np.float64) for k in per_env]),
        segments=cut,
        sim_config=config,
        device=device,
        **{**env, **overrides},
    )


def generalist_result(
    generalist: Generalist,
    contours: Sequence[Contour],
    pinches: Sequence[np.ndarray],
    segments: Sequence[Sequence[np.ndarray]] | None,
    trials: int,
    config: SimConfig,
    device: str | None,
    seed: int,
    on_step: StepCallback | None = None,
    allow_infeasible_pinch: bool = False,
    gains: Sequence[float] | None = None,
    arm: ArmModel | None = None,
    members: Sequence[int] | None = None,
) -> MethodResult:
    """``generalist`` on every (contour, trial) in one batch, zero-shot, paired with the baselines' trials
    of :func:`agents.evaluation.evaluate_suite` (seeded ``seed``: trial t of contour k sees the noise of
    their env ``k * trials + t``). ``gains``: per contour, a factor on the generalist's moves there (None or
    1: its moves as they are; 0: it holds still, no move or the stay action every step: fixed tension's
    trials, bit for bit). ``arm``: the cutting arm the pinch points must avoid (default: the paper's), as
    :func:`agents.evaluation.run_method` judges them for the other methods. ``members``: per contour, which
    of :attr:`Generalist.actors` plays there (None: its own policy everywhere)."""
    from agents.evaluation import MethodResult
    from agents.policies import policy_errors
    from envs.vector import PatternCutVecEnv

    options = generalist_options(
        generalist, contours, pinches, segments, config, trials, device,
        allow_infeasible_pinch=allow_infeasible_pinch, **({} if arm is None else {"arm": arm}),
    )  # fmt: skip
    actor = generalist.actor
    if members is not None and any(members):
        actor = _chosen(generalist.actors, np.repeat(np.asarray(members, dtype=np.int64), trials))
    if gains is not None:
        actor = _scaled(actor, np.repeat(gains, trials))
    env = PatternCutVecEnv(len(contours) * trials, options)
    out = policy_errors(actor, env, seed=seed + 1, on_step=on_step, paired_noise=(seed, 0))
    problems = env.task.pinch_problems
    rollouts = [
        {
            **{k: np.asarray(out[k])[c * trials : (c + 1) * trials] for k in SCORE_KEYS},
            "pinch": np.asarray(pinches[c], dtype=np.float64),
            "pinch_problem": problems[c * trials],
        }
        for c in range(len(contours))
    ]
    return MethodResult.from_rollouts(rollouts)


VALIDATION_EPISODES = 8
"""Validation episodes per contour and option (pinch candidate, gain), seeded apart from the evaluation's
(:data:`agents.policies.VALIDATION_SEED_OFFSET`), on which the generalist chooses where to pinch and how
strongly to act, and as many fresh ones on which its choice must cut better than holding still to be played
(:func:`guarded_result`)."""

Candidate = tuple[np.ndarray, Sequence[np.ndarray] | None]
"""Where a contour is cut: a pinch point and the segments in cutting order (None: the whole contour)."""


@dataclass(frozen=True)
class Guarded:
    """What :func:`guarded_result` played and why."""

    result: MethodResult
    """Per contour, the generalist at its chosen candidate and gain, or holding still (fixed tension) at the
    first candidate."""
    played: MethodResult | None
    """The generalist's own trials at its chosen candidate and gain on every contour, where it holds still
    too (None where it held still somewhere and they were not asked for)."""
    plays: np.ndarray
    """(num_contours,) bool: the generalist's choice cut better than holding still on the confirmation
    episodes, and plays."""
    chosen: list[int]
    """Per contour, the index of the candidate the generalist validated best at."""
    gain: np.ndarray
    """(num_contours,) the factor on its moves it validated best with there (1: its moves as they are)."""
    member: np.ndarray
    """(num_contours,) which of :attr:`Generalist.actors` validated best there (0: its own policy)."""
    validation: list[np.ndarray]
    """Per contour, the generalist's mean validation error (vertices) at each candidate, its moves as they
    are (its best member's there)."""
    best: np.ndarray
    """(num_contours,) its mean error at the chosen candidate and gain on the confirmation episodes."""
    still: np.ndarray
    """(num_contours,) holding still's mean error at the first candidate on the confirmation episodes."""


def guarded_result(
    generalist: Generalist,
    contours: Sequence[Contour],
    candidates: Sequence[Sequence[Candidate]],
    trials: int,
    config: SimConfig,
    device: str | None,
    seed: int,
    on_step: StepCallback | None = None,
    arm: ArmModel | None = None,
    played_everywhere: bool = False,
    gains: Sequence[float] = GENERALIST_GAINS,
    finalists: int = GENERALIST_FINALISTS,
) -> Guarded:
    """``generalist`` zero-shot, contour by contour, where it validates best among ``candidates[c]``
    (pinch points with their cuts; the first is the plan's) and ``gains`` (factors on its moves; a generalist
    with discrete actions plays its own), if that beats holding still at the first candidate; else holding
    still there (fixed tension).

    Validation: :data:`VALIDATION_EPISODES` noisy episodes per option, seeded ``seed`` +
    :data:`~agents.policies.VALIDATION_SEED_OFFSET`: every candidate with the moves of each of its
    :attr:`~Generalist.actors` as they are, then each one's :data:`~agents.config.GAIN_SHORTLIST` best
    candidates with each other gain (a batch each: each env draws a noise stream of its own); the lowest
    mean error wins (a tie keeps the earlier: the gain of 1, the generalist's own policy, the
    better-ranked candidate); with ``finalists`` > 1, each contour's best ``finalists`` options play again on
    as many fresh episodes (seeded ``VALIDATION_SEED_OFFSET`` beyond the confirmation's) and the lowest mean
    over both wins. The lowest of many noisy means is lower than what the option cuts, so the
    winner then plays against holding still on as many fresh episodes (seeded ``VALIDATION_SEED_OFFSET``
    further on, paired env by env): it plays where it cuts better there (a tie holds still). The trials are
    one batch of :func:`generalist_result`'s (paired with the baselines'), in which it holds still on the
    contours where it does not play: fixed tension's trials there, and ``on_step`` sees what is played.
    ``played_everywhere``: also play the generalist's trials where it holds still (``played``)."""
    from agents.evaluation import run_method
    from agents.policies import VALIDATION_SEED_OFFSET

    others = [g for g in _gains(gains, generalist) if g != 1.0]
    validation_seed, n = seed + VALIDATION_SEED_OFFSET, VALIDATION_EPISODES
    count = len(generalist.actors)

    def validate(options: list[tuple[int, int, float, int]], seed: int = validation_seed) -> np.ndarray:
        at = [candidates[c][k] for c, k, *_ in options]  # options: (contour, candidate, gain, actor)
        return generalist_result(
            generalist, [contours[c] for c, *_ in options], [p for p, _ in at], _cuts(at), n, config, device,
            seed, gains=[g for _, _, g, _ in options] if others else None, arm=arm,
            members=[m for *_, m in options],
        ).error_vertices.mean(axis=1)  # fmt: skip

    options = [(c, k, 1.0, m) for c, listed in enumerate(candidates) for m in range(count)
               for k in range(len(listed))]  # fmt: skip
    scores = validate(options)
    bounds = np.cumsum([0] + [count * len(listed) for listed in candidates])
    per_member = [scores[bounds[c] : bounds[c + 1]].reshape(count, -1) for c in range(len(contours))]
    validation = [v.min(axis=0) for v in per_member]
    shortlist = [np.argsort(v, axis=1, kind="stable")[:, :GAIN_SHORTLIST] for v in per_member]
    more = [(c, int(k), g, m) for c, top in enumerate(shortlist) for m in range(count) for k in top[m]
            for g in others]  # fmt: skip
    if more:
        options, scores = options + more, np.concatenate([scores, validate(more)])
    ranked = [sorted((s, i) for i, ((c, *_), s) in enumerate(zip(options, scores, strict=True))
                     if c == contour)[:finalists] for contour in range(len(contours))]  # fmt: skip
    confirmation_seed = validation_seed + VALIDATION_SEED_OFFSET
    if finalists > 1:
        pool = [i for top in ranked for _, i in top]
        fresh = validate([options[i] for i in pool], confirmation_seed + VALIDATION_SEED_OFFSET)
        again = dict(zip(pool, fresh, strict=True))
        ranked = [[((s + again[i]) / 2, i) for s, i in top] for top in ranked]
    kept = [min(top) for top in ranked]
    chosen = [options[i][1] for _, i in kept]
    gain = np.array([options[i][2] for _, i in kept])
    member = np.array([options[i][3] for _, i in kept], dtype=np.int64)
    first, best_at = [listed[0] for listed in candidates], [candidates[c][k] for c, k in enumerate(chosen)]
    best = generalist_result(
        generalist, contours, [p for p, _ in best_at], _cuts(best_at), n, config, device, confirmation_seed,
        gains=None if not others else gain, arm=arm, members=member,
    ).error_vertices.mean(axis=1)  # fmt: skip
    still = run_method(
        contours, [p for p, _ in first], None, n, config, device, confirmation_seed, segments=_cuts(first),
        arm=arm,
    ).error_vertices.mean(axis=1)  # fmt: skip
    plays = best < still
    at = [candidates[c][k if play else 0] for c, (k, play) in enumerate(zip(chosen, plays, strict=True))]
    played_gains = np.where(plays, gain, 0.0)
    result = generalist_result(
        generalist, contours, [p for p, _ in at], _cuts(at), trials, config, device, seed, on_step,
        gains=None if (played_gains == 1.0).all() else played_gains, arm=arm, members=member,
    )  # fmt: skip
    played = result if plays.all() else None
    if played_everywhere and played is None:
        played = generalist_result(
            generalist, contours, [p for p, _ in best_at], _cuts(best_at), trials, config, device, seed,
            gains=None if (gain == 1.0).all() else gain, arm=arm, members=member,
        )  # fmt: skip
    return Guarded(result, played, plays, chosen, gain, member, validation, best, still)


def generalist_cut(
    generalist: Generalist,
    contour: Contour,
    config: SimConfig,
    seed: int = 0,
    device: str | None = None,
    arm: ArmModel | None = None,
) -> Candidate:
    """Where ``generalist``'s own policy (not its members) plays ``contour`` zero-shot with its moves as they
    are, and where fine-tuning it starts: the contour planned as ``evaluate`` plans it
    (:data:`~agents.config.EVALUATION_CANDIDATES` pinch candidates, noise-free), then the candidate (its
    pinch point and segments in order) where it validates best (:func:`guarded_result`'s validation, seeded
    from ``seed``)."""
    from agents.config import EVALUATION_CANDIDATES
    from warpcut.planning import ArmModel, plan_cut

    arm = arm or ArmModel()
    noise_free = config.replace(noise_std=0.0)
    plan = plan_cut(
        contour, noise_free, num_candidates=EVALUATION_CANDIDATES, seed=seed, device=device, arm=arm
    )
    candidates = [(np.asarray(c["pinch"]), plan.ordered_segments(c["order"])) for c in plan.ranked()]
    own = replace(generalist, members=())  # fine-tuning starts from its own policy
    guarded = guarded_result(own, [contour], [candidates], 1, config, device, seed, arm=arm, gains=(1.0,))
    return candidates[guarded.chosen[0]]


def _cuts(listed: Sequence[Candidate]) -> list | None:
    """The segments of each candidate listed, or None where they cut the whole contour."""
    return None if listed[0][1] is None else [segments for _, segments in listed]


def _gains(gains: Sequence[float], generalist: Generalist) -> tuple[float, ...]:
    """``gains`` checked (:func:`agents.config.check_gains`); (1,) for a generalist with discrete actions,
    whose choice among moves a factor cannot scale."""
    listed = check_gains(gains)
    return listed if generalist.settings["env"].get("action_type") == "continuous" else (1.0,)


def _scaled(actor: torch.nn.Module, gains: np.ndarray) -> torch.nn.Module:
    """``actor`` with its action multiplied by ``gains``, one per env: 0 zeroes it, no move (continuous) or
    stay (discrete); 1 leaves it as it is, bit for bit."""
    import torch

    factor = torch.as_tensor(np.asarray(gains, dtype=np.float32)).reshape(-1, 1)

    class Scaled(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.actor = actor

        def forward(self, obs):
            return self.actor(obs) * factor

    return Scaled()


def _chosen(actors: Sequence[torch.nn.Module], index: np.ndarray) -> torch.nn.Module:
    """One policy of the batch: env ``e`` acts as ``actors[index[e]]`` (each member on its own envs'
    observations)."""
    import torch

    groups = [(actors[m], torch.as_tensor(np.flatnonzero(index == m))) for m in np.unique(index)]

    class Chosen(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.actors = torch.nn.ModuleList(actors)

        def forward(self, obs):
            out = None
            for actor, rows in groups:
                part = actor(obs[rows])
                if out is None:
                    out = part.new_empty((len(index), *part.shape[1:]))
                out[rows] = part
            return out

    return Chosen()


def student_moves(
    generalist: Generalist,
    contour: Contour,
    pinch: np.ndarray,
    segments: Sequence[np.ndarray] | None,
    config: SimConfig,
    seed: int,
    device: str | None = None,
) -> np.ndarray:
    """``(T, 3)`` the grasp moves (mm) ``generalist`` makes, deterministic, in one episode of cutting
    ``contour`` (``segments``, at ``pinch``) on ``config``'s sheet with the noise of ``seed``: what a teacher
    tethered to it starts from (``warpcut teachers --set near=DIR``)."""
    from agents.policies import policy_errors
    from envs.vector import PatternCutVecEnv

    options = generalist_options(
        generalist, [contour], [pinch], None if segments is None else [segments], config, 1, device,
        allow_infeasible_pinch=True,
    )  # fmt: skip
    moves: list[np.ndarray] = []

    def record(task, last_moves) -> None:
        if last_moves is not None:
            moves.append(np.array(last_moves[0], dtype=np.float32))

    policy_errors(generalist.actor, PatternCutVecEnv(1, options), seed=seed, on_step=record)
    return np.stack(moves) if moves else np.zeros((0, 3), dtype=np.float32)


def fine_tuning_defaults(job, explicit: set[str]):
    """``job`` (a :class:`agents.jobs.TrainJob` with ``init``) observing and acting as its generalist does
    (its look-ahead, fiducials, actions) and, for es, with its network (widths, activation, normaliser,
    feedback, scheduled gains) and its MLP's σ and step (:data:`ES_FIELDS`), where ``explicit`` (the dotted
    keys given) does not say otherwise. The learner is one that fine-tunes (es) unless ``train.algo`` is
    given."""
    import dataclasses

    from agents.algorithms import ALGORITHMS

    settings = generalist_settings(job.init)
    own, policy = settings["env"], settings.get("policy", {})
    layout = ("num_fiducials", "contour_features", "lookahead", "action_type", "allow_z")
    given = {name: own[name] for name in layout if name in own and f"env.{name}" not in explicit}
    train = job.train
    if "train.algo" not in explicit and not ALGORITHMS[train.algo].fine_tunes:
        fine_tuner = next(name for name, entry in ALGORITHMS.items() if entry.fine_tunes)
        train = dataclasses.replace(train, algo=fine_tuner)
    if train.algo == "es":  # fine-tuning is es's (the others refuse init)
        net = {k: v for k, v in policy.items() if k in POLICY_FIELDS and f"train.{k}" not in explicit}
        es = {k: policy[k] for k in ES_FIELDS if k in policy and f"train.es.{k}" not in explicit}
        train = dataclasses.replace(train, **net, es=dataclasses.replace(train.es, **es))
    return dataclasses.replace(job, env=dataclasses.replace(job.env, **given), train=train)
