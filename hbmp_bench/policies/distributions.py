"""A categorical distribution for rsl-rl's pluggable ``Distribution``: the five behaviors are discrete.

rsl-rl stores actions as float tensors of shape (batch, num_actions). A behavior is one index, so
the model's ``output_dim`` (rsl-rl's ``num_actions``) is 1 and the distribution asks the network
for ``num_categories`` logits (:attr:`CategoricalDistribution.input_dim`). Samples and the
deterministic output are the index as a float, shape (batch, 1).

Use it in a model config as::

    distribution_cfg = {"class_name": "hbmp_bench.policies.distributions:CategoricalDistribution",
                        "num_categories": NUM_BEHAVIORS}
"""

from __future__ import annotations

import torch
import torch.nn as nn
from rsl_rl.modules.distribution import Distribution
from torch.distributions import Categorical

from hbmp_bench.vocabulary import NUM_BEHAVIORS


class CategoricalDistribution(Distribution):
    """Categorical over ``num_categories`` behaviors, parameterised by logits.

    Args:
        output_dim: rsl-rl's action dimension; must be 1 (one behavior index per decision).
        num_categories: number of behaviors (5 in the paper's order).
        init_logit_scale: gain of the orthogonal init of the last layer; small values start the
            policy near uniform (PPO practice).
        temperature: the distribution is ``softmax(logits / temperature)`` (1: the paper's softmax;
            below 1 sharper, so that a policy sampled in training acts closer to its greedy self). The
            deterministic output, the most likely behavior, does not depend on it.
    """

    def __init__(self, output_dim: int = 1, num_categories: int = NUM_BEHAVIORS, init_logit_scale: float = 0.01,
                 temperature: float = 1.0) -> None:
        if not temperature > 0:
            raise ValueError(f"temperature must be > 0, got {temperature}")
        if output_dim != 1:
            raise ValueError(f"a categorical action is one index: output_dim must be 1, got {output_dim}")
        if num_categories < 2:
            raise ValueError(f"num_categories must be >= 2, got {num_categories}")
        super().__init__(output_dim)
        self.num_categories = num_categories
        self.init_logit_scale = init_logit_scale
        self.temperature = float(temperature)
        self._distribution: Categorical | None = None
        Categorical.set_default_validate_args(False)

    def update(self, mlp_output: torch.Tensor) -> None:
        """Set the distribution from logits (batch, num_categories), divided by the temperature."""
        self._distribution = Categorical(logits=mlp_output / self.temperature)  # exact at 1

    def sample(self) -> torch.Tensor:
        """(batch, 1) float behavior indices."""
        return self._distribution.sample().unsqueeze(-1).to(torch.float32)  # type: ignore[union-attr]

    def deterministic_output(self, mlp_output: torch.Tensor) -> torch.Tensor:
        """(batch, 1) float index of the most likely behavior."""
        return mlp_output.argmax(dim=-1, keepdim=True).to(torch.float32)

    def as_deterministic_output_module(self) -> nn.Module:
        return _ArgmaxOutput()

    @property
    def input_dim(self) -> int:
        return self.num_categories

    @property
    def probs(self) -> torch.Tensor:
        """(batch, num_categories) behavior probabilities."""
        return self._distribution.probs  # type: ignore[union-attr]

    @property
    def mean(self) -> torch.Tensor:
        """(batch, 1) expected index (for logging only)."""
        idx = torch.arange(self.num_categories, dtype=self.probs.dtype, device=self.probs.device)
        return (self.probs * idx).sum(-1, keepdim=True)

    @property
    def std(self) -> torch.Tensor:
        """(batch, 1) standard deviation of the index (rsl-rl logs it as the action spread)."""
        idx = torch.arange(self.num_categories, dtype=self.probs.dtype, device=self.probs.device)
        var = (self.probs * idx**2).sum(-1, keepdim=True) - self.mean**2
        return var.clamp_min(0.0).sqrt()

    @property
    def entropy(self) -> torch.Tensor:
        """(batch,) entropy [nats]."""
        return self._distribution.entropy()  # type: ignore[union-attr]

    @property
    def params(self) -> tuple[torch.Tensor, ...]:
        """(normalised logits (batch, num_categories),), stored by the rollout for the KL."""
        return (self._distribution.logits,)  # type: ignore[union-attr]

    def log_prob(self, outputs: torch.Tensor) -> torch.Tensor:
        """(batch,) log-probability of the indices ``outputs`` (batch, 1)."""
        return self._distribution.log_prob(outputs.squeeze(-1).round().long())  # type: ignore[union-attr]

    def kl_divergence(self, old_params: tuple[torch.Tensor, ...], new_params: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """(batch,) KL(old || new), from log-probabilities: finite where one side's probability underflows to 0
        and the other's does not (torch's categorical KL is inf there; sharp policies, e.g. at a temperature
        below 1, logged an infinite KL to the ``il`` anchor)."""
        old, new = Categorical(logits=old_params[0]), Categorical(logits=new_params[0])
        terms = old.probs * (old.logits - new.logits)  # torch's own terms, without its inf where new.probs == 0
        return torch.where(old.probs == 0, 0.0, terms).sum(-1)

    def init_mlp_weights(self, mlp: nn.Module) -> None:
        """Near-uniform start: small orthogonal init of the logits layer."""
        last = [m for m in mlp.modules() if isinstance(m, nn.Linear)][-1]
        nn.init.orthogonal_(last.weight, gain=self.init_logit_scale)
        nn.init.zeros_(last.bias)


class _ArgmaxOutput(nn.Module):
    """Export-friendly deterministic output: the index of the largest logit, (batch, 1) float."""

    def forward(self, mlp_output: torch.Tensor) -> torch.Tensor:
        return mlp_output.argmax(dim=-1, keepdim=True).to(torch.float32)
