"""Learned agents: il (DAgger), hbmp (PPO, r_k + r_T), hbmp-s (PPO, r_T only), flat (PPO on controls from a random
actor, on CARLA's RL reward: Tab. I's RL baseline),
flat-il (DAgger on the expert's controls, CIL) and flat-ilrl (PPO on controls from flat-il, CIRL).

Each loads a checkpoint shipped in ``hbmp_bench/agents/checkpoints/<name>.pt`` (with a model card
``<name>.md`` beside it), produced by the package's own ``hbmp-bench train <name>``; any other
checkpoint loads with ``load_agent("path/to/policy.pt")``. Files are read with
``torch.load(weights_only=True)``; torch is imported only when a learned agent is made.

The policy acts greedily: a behavior policy takes its most likely *feasible* behavior (``info["action_mask"]``,
a lane change needs a lane on that side). The env would run an infeasible choice as ``keep``, which keeps the
current speed: at standstill that is a trap a deterministic policy never leaves (measured: the DAgger ``il``
asked change_right on a one-lane road 173 times in a row at 0 m/s in Town03 Straight, hbmp suite episode 0, and
timed out; the expert, whose data it learnt, never changes lanes at standstill). A checkpoint records the
observation it was
trained on (``env_kwargs``): evaluate a vehicle-centric policy on an env made with
``observation="vehicle_centric"``.
"""

from __future__ import annotations

import hashlib
import os
from importlib import resources
from typing import Any

import numpy as np

from hbmp_bench.agents.base import register_agent

TRAIN_COMMANDS = {
    "il": "hbmp-bench train il --fidelity continuous --road-profile metric --episodes 2000 --workers 2 --seed 0 "
          "--density regular --out runs/il",
    "hbmp": "hbmp-bench train hbmp --episodes 6000 --workers 2 --seed 0 --density regular --out runs/hbmp",
    "hbmp-s": "hbmp-bench train hbmp-s --episodes 6000 --workers 2 --seed 0 --density regular --out runs/hbmp-s",
    "flat": "hbmp-bench train flat --reward carla --agents 8 --episodes 6000 --workers 2 --seed 0 --density regular "
            "--ppo init_std=0.1 --ppo mini_batch_size=256 --ppo overlap_update=true --validate-every 500 "
            "--validate-episodes 10 --out runs/flat",
    "flat-il": "hbmp-bench train flat-il --episodes 200 --workers 1 --seed 0 --density regular --validate-every 50 "
               "--validate-episodes 5 --out runs/flat-il",
    "flat-ilrl": "hbmp-bench train flat --init flat-il --agents 8 --episodes 3000 --workers 2 --seed 0 --density regular "
                 "--ppo init_std=0.1 --ppo anchor_kl=reverse --ppo anchor_coef=0.1 --ppo gamma=0.999 --ppo lam=0.995 "
                 "--ppo mini_batch_size=256 --ppo overlap_update=true --validate-every 250 --out runs/flat-ilrl",
}
"""How each shipped checkpoint is (re)produced; the model card beside it has the exact command used. The third
word is the training kind the checkpoint records (``flat-ilrl`` is the ``flat`` kind started from ``flat-il``)."""


def trained_kind(name: str) -> str:
    """The training kind of the shipped agent ``name`` (its checkpoint's ``kind``): ``flat`` for ``flat-ilrl``."""
    return TRAIN_COMMANDS[name].split()[2]

OBSERVATION_OPTIONS = ("observation", "road_profile")
"""Environment options that change what the policy sees (so an evaluation must match them)."""


def shipped_checkpoint(name: str) -> str:
    """Path of the checkpoint shipped for ``name``; a clear error naming the train command if absent."""
    if name not in TRAIN_COMMANDS:
        from hbmp_bench.errors import UnknownNameError

        raise UnknownNameError("learned agent", name, TRAIN_COMMANDS)
    path = str(resources.files("hbmp_bench.agents") / "checkpoints" / f"{name}.pt")
    if not os.path.isfile(path):
        raise FileNotFoundError(
            f"no shipped checkpoint for agent {name!r} (hbmp_bench/agents/checkpoints/{name}.pt). Produce it with "
            f"`{TRAIN_COMMANDS[name]}`, then copy runs/{name}/best.pt (policy.pt without --validate-every) to "
            f"that place, or load any checkpoint with --agent path/to/policy.pt")
    return path


def checkpoint_fingerprint(path: str | os.PathLike) -> str:
    """sha256 of a checkpoint file's bytes (first 16 hex digits): which weights drove an evaluation."""
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:16]


class LearnedAgent:
    """A trained policy from a checkpoint file.

    Args:
        checkpoint: path of a ``.pt`` file written by ``hbmp-bench train``.
        name: agent name in records (default: the checkpoint's kind, or the file name).
        device: torch device.

    Attributes:
        kind: ``il``, ``hbmp``, ``hbmp-s``, ``flat`` or ``flat-il``.
        env_kwargs: the observation options the policy needs from the env (``observation``), to
            pass to ``make``; empty for the default deformed M_t.
        trained_env: every environment option of its training run (id, fidelity, density ...).
        fingerprint: :func:`checkpoint_fingerprint` of the file, so a resumed evaluation never mixes
            two checkpoints under one name and a leaderboard entry names the weights it measured.
    """

    def __init__(self, checkpoint: str, name: str | None = None, device: str = "cpu"):
        import torch

        from hbmp_bench.policies.checkpoints import build_actor, load_checkpoint

        ckpt = load_checkpoint(checkpoint)
        self.checkpoint = checkpoint
        self.fingerprint = checkpoint_fingerprint(checkpoint)
        self.kind = ckpt["kind"]
        self.name = name or self.kind
        model = ckpt["model"]
        self.trained_env = dict(model["env"])
        self.env_kwargs = {k: v for k, v in self.trained_env.items() if k in OBSERVATION_OPTIONS}
        self.discrete = model["action_space"] == "discrete"
        self.env_factory = None if self.discrete else "hbmp_bench.envs.control_env:ControlEnv"
        """The env a control policy (flat, flat-il) needs; None: the behavior env."""
        mask_group = model["actor"].get("action_mask_group")
        self._groups = list(model["obs_groups"]["actor"]) + ([mask_group] if mask_group else [])
        self._torch = torch
        self.device = device
        self.actor = build_actor(ckpt).to(device)

    def reset(self, info: dict[str, Any]) -> None:
        pass

    def _batch(self, observation: dict[str, Any], info: dict[str, Any]):
        from tensordict import TensorDict

        torch = self._torch
        groups = {}
        for key in self._groups:
            value = info["action_mask"] if key == "action_mask" and key not in observation else observation[key]
            groups[key] = torch.as_tensor(np.asarray(value, dtype=np.float32), device=self.device).unsqueeze(0)
        return TensorDict(groups, batch_size=[1], device=self.device)

    def act(self, observation: dict[str, Any], info: dict[str, Any]):
        """The behavior index (int) for behavior policies; the control vector (np.ndarray) for ``flat`` and
        ``flat-il``."""
        if self.discrete:
            probabilities = self.behavior_probabilities(observation, info)
            mask = np.asarray(info.get("action_mask", np.ones_like(probabilities)), dtype=bool)
            return int(np.argmax(np.where(mask, probabilities, -1.0)) if mask.any() else np.argmax(probabilities))
        with self._torch.inference_mode():
            out = self.actor(self._batch(observation, info))[0]
        # the Gaussian mean is unbounded; training clips controls to [-1, 1] in the env, so does this
        return np.clip(out.cpu().numpy(), -1.0, 1.0).astype(np.float32)

    def act_batch(self, observations: dict[str, dict[str, Any]], infos: dict[str, dict[str, Any]]) -> dict[str, Any]:
        """:meth:`act` for many vehicles in one forward pass: ``observations`` / ``infos`` keyed by vehicle
        (every vehicle of a scene that decides now, ``agents.scene.SceneAgent``); returns their actions by
        the same keys (the same as one :meth:`act` each, up to the last float bit of a batched matmul)."""
        from tensordict import TensorDict

        torch, names = self._torch, list(observations)
        if not names:
            return {}
        groups = {}
        for key in self._groups:
            rows = [infos[n]["action_mask"] if key == "action_mask" and key not in observations[n]
                    else observations[n][key] for n in names]
            groups[key] = torch.as_tensor(np.stack([np.asarray(r, dtype=np.float32) for r in rows]), device=self.device)
        batch = TensorDict(groups, batch_size=[len(names)], device=self.device)
        with torch.inference_mode():
            if not self.discrete:
                out = np.clip(self.actor(batch).cpu().numpy(), -1.0, 1.0).astype(np.float32)
                return {n: out[k] for k, n in enumerate(names)}
            distribution = self.actor.distribution
            distribution.update(self.actor.distribution_input(batch))
            probabilities = distribution.probs.cpu().numpy()
        actions = {}
        for k, n in enumerate(names):
            mask = np.asarray(infos[n].get("action_mask", np.ones(probabilities.shape[1])), dtype=bool)
            actions[n] = int(np.argmax(np.where(mask, probabilities[k], -1.0)) if mask.any()
                             else np.argmax(probabilities[k]))
        return actions

    def behavior_probabilities(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        """(5,) the policy's behavior probabilities (behavior policies only): its own distribution's, so a
        policy trained at a sampling temperature reports the probabilities it was trained with."""
        if not self.discrete:
            raise ValueError(f"{self.kind!r} is not a behavior policy")
        with self._torch.inference_mode():
            distribution = self.actor.distribution
            distribution.update(self.actor.distribution_input(self._batch(observation, info)))
            return distribution.probs[0].cpu().numpy()


def _shipped(name: str):
    def make(checkpoint: str | None = None, **kwargs: Any) -> LearnedAgent:
        return LearnedAgent(checkpoint or shipped_checkpoint(name), name=name, **kwargs)

    make.__doc__ = f"The shipped ``{name}`` policy (``checkpoint=`` loads another file instead)."
    return make


for _name in TRAIN_COMMANDS:
    register_agent(_name)(_shipped(_name))
