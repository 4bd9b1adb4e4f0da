"""The paper's actor and critic network as an rsl-rl model (resolved through ``class_name``).

Paper ("Network and Training"): the M_t branch is three convolutions and one fully connected
layer, the R_t branch is fully connected layers, the two outputs are concatenated and fed into
the final fully connected layers; the actor ends in a softmax over the behaviors, the critic in a
state value. :class:`BehaviorNetwork` builds exactly that from rsl-rl parts: ``rsl_rl.modules.CNN``
for the convolutions, ``rsl_rl.modules.MLP`` for the final layers, and a pluggable
``Distribution`` for the output (:class:`~hbmp_bench.policies.distributions.CategoricalDistribution`
for the behaviors; rsl-rl's ``GaussianDistribution`` for the flat baseline's controls).

rsl-rl's own ``CNNModel`` concatenates the raw 1-D groups with the CNN features, with no FC
layer on either branch, so it is not the paper's network; hence this subclass of ``MLPModel``.

The paper does not give layer sizes; the defaults here (conv 16-32-32 with kernels 5-3-3,
stride 2; M_t FC 256; R_t FCs 64-64; final FCs 256-128; ReLU) are this package's choice, kept
small so that training runs on a laptop CPU (a 128-sample update takes ~15 ms on one core).

Action masking (optional, off by default as in the paper): with ``action_mask_group`` set, the
logits of infeasible behaviors (mask < 0.5 in that observation group) are replaced by a large
negative number before the softmax, so the policy never picks them and PPO's log-probabilities
and entropy are over the feasible ones. Without it the env executes an infeasible behavior as
``keep``.
"""

from __future__ import annotations

import torch
import torch.nn as nn
from rsl_rl.models import MLPModel
from rsl_rl.modules import CNN, HiddenState
from rsl_rl.utils import resolve_nn_activation
from tensordict import TensorDict

from hbmp_bench.vocabulary import NUM_BEHAVIORS

MASKED_LOGIT = -1.0e8
"""Logit given to a masked behavior (finite, so entropies and KLs stay finite)."""

MODEL_CLASS = "hbmp_bench.policies.networks:BehaviorNetwork"
CATEGORICAL_CLASS = "hbmp_bench.policies.distributions:CategoricalDistribution"
GAUSSIAN_CLASS = "rsl_rl.modules.distribution:GaussianDistribution"


class BehaviorNetwork(MLPModel):
    """Two-branch network: M_t → 3 conv + FC, R_t → FCs, concatenated → FCs → output.

    Every 2-D observation group of ``obs_set`` (shape (B, C, H, W)) gets its own conv branch;
    all 1-D groups (shape (B, D)) are concatenated into the R_t branch.

    Args:
        obs, obs_groups, obs_set, output_dim, activation, obs_normalization, distribution_cfg:
            as rsl-rl's ``MLPModel`` (normalisation applies to the 1-D groups only).
        hidden_dims: the final FC layers after the concatenation.
        conv_channels / conv_kernels / conv_strides: the three convolutions of the M_t branch.
        grid_fc_dim: width of the M_t branch's FC layer.
        vector_dims: widths of the R_t branch's FC layers.
        action_mask_group: observation group holding the (B, num_categories) feasibility mask, or
            None for no masking; it must not also be an input group.

    Shapes: ``forward(obs)`` returns (B, output_dim); with a categorical distribution that is
    the behavior index (B, 1).
    """

    def __init__(
        self,
        obs: TensorDict,
        obs_groups: dict[str, list[str]],
        obs_set: str,
        output_dim: int,
        hidden_dims: tuple[int, ...] | list[int] = (256, 128),
        activation: str = "relu",
        obs_normalization: bool = False,
        distribution_cfg: dict | None = None,
        conv_channels: tuple[int, ...] | list[int] = (16, 32, 32),
        conv_kernels: tuple[int, ...] | list[int] = (5, 3, 3),
        conv_strides: tuple[int, ...] | list[int] = (2, 2, 2),
        grid_fc_dim: int = 256,
        vector_dims: tuple[int, ...] | list[int] = (64, 64),
        action_mask_group: str | None = None,
    ) -> None:
        if not (len(conv_channels) == len(conv_kernels) == len(conv_strides) == 3):
            raise ValueError("the M_t branch has three convolutions: give three channels, kernels and strides")
        if not vector_dims or not hidden_dims:
            raise ValueError("vector_dims and hidden_dims need at least one layer each")
        self.action_mask_group = action_mask_group
        self.grid_fc_dim = int(grid_fc_dim)
        self.vector_dims = tuple(int(d) for d in vector_dims)
        super().__init__(obs, obs_groups, obs_set, output_dim, hidden_dims, activation, obs_normalization,
                         distribution_cfg)
        self.grid_encoders = nn.ModuleDict()
        for group, (channels, hw) in self.grid_shapes.items():
            cnn = CNN(input_dim=hw, input_channels=channels, output_channels=list(conv_channels),
                      kernel_size=list(conv_kernels), stride=list(conv_strides), activation=activation)
            self.grid_encoders[group] = nn.Sequential(
                cnn, nn.Linear(int(cnn.output_dim), self.grid_fc_dim), resolve_nn_activation(activation))
        self.vector_encoder: nn.Module | None = None
        if self.obs_groups:
            layers, width = [], self.obs_dim
            for dim in self.vector_dims:
                layers += [nn.Linear(width, dim), resolve_nn_activation(activation)]
                width = dim
            self.vector_encoder = nn.Sequential(*layers)
        if action_mask_group is not None:
            if self.distribution is None or self.distribution.input_dim != obs[action_mask_group].shape[-1]:
                raise ValueError("action masking needs a categorical output with one logit per mask entry")

    # ------------------------------------------------------------ structure
    def _get_obs_dim(self, obs: TensorDict, obs_groups: dict[str, list[str]], obs_set: str) -> tuple[list[str], int]:
        """Split the set's groups into 2-D (conv branches) and 1-D (R_t branch) ones."""
        groups_1d, dim_1d, self.grid_shapes = [], 0, {}
        for group in obs_groups[obs_set]:
            if group == self.action_mask_group:
                raise ValueError(f"the action mask group {group!r} cannot also be a network input")
            shape = obs[group].shape
            if len(shape) == 4:
                self.grid_shapes[group] = (int(shape[1]), (int(shape[2]), int(shape[3])))
            elif len(shape) == 2:
                groups_1d.append(group)
                dim_1d += int(shape[-1])
            else:
                raise ValueError(f"observation group {group!r} has shape {tuple(shape)}; valid: (B, D) or (B, C, H, W)")
        return groups_1d, dim_1d

    def _get_latent_dim(self) -> int:
        return len(self.grid_shapes) * self.grid_fc_dim + (self.vector_dims[-1] if self.obs_groups else 0)

    # -------------------------------------------------------------- forward
    def get_latent(self, obs: TensorDict, masks: torch.Tensor | None = None, hidden_state: HiddenState = None) -> torch.Tensor:
        """(B, latent) = [FC(conv(M_t)) for each grid, FCs(R_t)] concatenated."""
        parts = [self.grid_encoders[g](obs[g]) for g in self.grid_shapes]
        if self.vector_encoder is not None:
            parts.append(self.vector_encoder(super().get_latent(obs)))
        return torch.cat(parts, dim=-1)

    def distribution_input(self, obs: TensorDict) -> torch.Tensor:
        """The raw output before sampling: (B, num_categories) masked logits, or (B, output_dim)."""
        out = self.mlp(self.get_latent(obs))
        if self.action_mask_group is not None:
            out = out.masked_fill(obs[self.action_mask_group] < 0.5, MASKED_LOGIT)
        return out

    def forward(self, obs: TensorDict, masks: torch.Tensor | None = None, hidden_state: HiddenState = None,
                stochastic_output: bool = False) -> torch.Tensor:
        out = self.distribution_input(obs)
        if self.distribution is None:
            return out
        if stochastic_output:
            self.distribution.update(out)
            return self.distribution.sample()
        return self.distribution.deterministic_output(out)

    def as_jit(self) -> nn.Module:
        raise NotImplementedError("export of BehaviorNetwork is not supported; load its state dict instead")

    def as_onnx(self, verbose: bool = False) -> nn.Module:
        raise NotImplementedError("export of BehaviorNetwork is not supported; load its state dict instead")


NETWORK = {
    "hidden_dims": [256, 128],
    "activation": "relu",
    "conv_channels": [16, 32, 32],
    "conv_kernels": [5, 3, 3],
    "conv_strides": [2, 2, 2],
    "grid_fc_dim": 256,
    "vector_dims": [64, 64],
}
"""The architecture written into every model config (and so into every checkpoint), so a saved
policy rebuilds the same network even if the class defaults change."""


COMPACT_NETWORK = {**NETWORK, "hidden_dims": [128, 64], "grid_fc_dim": 64}
"""A smaller trunk of the same shape (81 k parameters against :data:`NETWORK`'s 282 k; 0.3 MB on disk against 1.1):
the imitation of the expert's controls (``flat-il``), whose checkpoint ships with the package."""


def behavior_model_cfgs(mask_actions: bool = False, num_categories: int = NUM_BEHAVIORS,
                        temperature: float = 1.0) -> tuple[dict, dict]:
    """rsl-rl ``actor`` and ``critic`` configs for the behavior policy (paper's network); ``temperature``:
    the categorical's (:class:`~hbmp_bench.policies.distributions.CategoricalDistribution`)."""
    distribution = {"class_name": CATEGORICAL_CLASS, "num_categories": num_categories}
    if temperature != 1.0:  # configs of the paper's softmax stay as they were recorded
        distribution["temperature"] = temperature
    actor = {"class_name": MODEL_CLASS, **NETWORK, "distribution_cfg": distribution}
    if mask_actions:
        actor["action_mask_group"] = "action_mask"
    critic = {"class_name": MODEL_CLASS, **NETWORK}
    return actor, critic


def control_model_cfgs(init_std: float = 0.5, network: dict | None = None) -> tuple[dict, dict]:
    """rsl-rl ``actor`` and ``critic`` configs for the flat baseline: same network (or ``network``, e.g.
    :data:`COMPACT_NETWORK`), Gaussian controls."""
    network = dict(NETWORK if network is None else network)
    actor = {"class_name": MODEL_CLASS, **network,
             "distribution_cfg": {"class_name": GAUSSIAN_CLASS,
                                  "init_std": init_std, "std_type": "log"}}
    return actor, {"class_name": MODEL_CLASS, **network}


def dummy_observations(obs_shapes: dict[str, tuple[int, ...]], batch: int = 1) -> TensorDict:
    """A zero TensorDict (batch, *shape) per group, to build a model without an environment."""
    return TensorDict({k: torch.zeros(batch, *shape) for k, shape in obs_shapes.items()}, batch_size=[batch])


def build_model(model_cfg: dict, obs_shapes: dict[str, tuple[int, ...]], obs_groups: dict[str, list[str]],
                obs_set: str, output_dim: int) -> MLPModel:
    """An rsl-rl model from its config (``class_name`` + kwargs) and the observation group shapes."""
    from rsl_rl.utils import resolve_class

    cls, kwargs = resolve_class(model_cfg)
    return cls(dummy_observations(obs_shapes), obs_groups, obs_set, output_dim, **kwargs)


def observation_shapes(obs: TensorDict) -> dict[str, tuple[int, ...]]:
    """Per-group shapes without the batch dimension."""
    return {k: tuple(int(s) for s in v.shape[1:]) for k, v in obs.items()}


def model_summary(model: nn.Module) -> str:
    """One line: parameter count."""
    return f"{type(model).__name__}: {sum(p.numel() for p in model.parameters()):,} parameters"


__all__ = ["COMPACT_NETWORK", "NETWORK", "BehaviorNetwork", "behavior_model_cfgs", "build_model", "control_model_cfgs",
           "dummy_observations", "observation_shapes"]
