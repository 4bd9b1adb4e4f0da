"""Categorical distribution, the paper's two-branch network, and TwoRatePPO updates (no SUMO)."""

import pytest
import torch
from rsl_rl.storage import RolloutStorage
from torch.distributions import Categorical

from hbmp_bench.policies.distributions import CategoricalDistribution
from hbmp_bench.policies.networks import (
    BehaviorNetwork,
    behavior_model_cfgs,
    build_model,
    control_model_cfgs,
    dummy_observations,
)
from hbmp_bench.training.ppo import PPOConfig, TwoRatePPO

SHAPES = {"occupancy": (1, 64, 36), "road": (10,), "action_mask": (5,)}
GROUPS = {"actor": ["occupancy", "road"], "critic": ["occupancy", "road"]}


def _random_obs(batch, seed=0):
    g = torch.Generator().manual_seed(seed)
    obs = dummy_observations(SHAPES, batch)
    obs["occupancy"] = (torch.rand(batch, 1, 64, 36, generator=g) < 0.1).float()
    obs["road"] = torch.rand(batch, 10, generator=g)
    obs["action_mask"] = torch.ones(batch, 5)
    return obs


def test_categorical_matches_torch_distributions():
    dist = CategoricalDistribution(num_categories=5)
    logits = torch.randn(7, 5, generator=torch.Generator().manual_seed(1))
    dist.update(logits)
    ref = Categorical(logits=logits)
    actions = torch.tensor([[0.0], [1.0], [2.0], [3.0], [4.0], [2.0], [0.0]])
    assert dist.log_prob(actions) == pytest.approx(ref.log_prob(actions.squeeze(-1).long()))
    assert dist.entropy == pytest.approx(ref.entropy())
    assert dist.log_prob(actions).shape == (7,) and dist.entropy.shape == (7,)
    sample = dist.sample()
    assert sample.shape == (7, 1) and sample.dtype == torch.float32 and ((sample >= 0) & (sample < 5)).all()
    assert torch.equal(dist.deterministic_output(logits).squeeze(-1).long(), logits.argmax(-1))
    other = torch.randn(7, 5)
    kl = dist.kl_divergence((logits,), (other,))
    assert kl == pytest.approx(torch.distributions.kl_divergence(ref, Categorical(logits=other)))
    assert dist.kl_divergence(dist.params, dist.params) == pytest.approx(torch.zeros(7), abs=1e-6)
    idx = torch.arange(5.0)
    assert dist.mean.squeeze(-1) == pytest.approx((ref.probs * idx).sum(-1))
    var = (ref.probs * idx**2).sum(-1) - (ref.probs * idx).sum(-1) ** 2
    assert dist.std.squeeze(-1) == pytest.approx(var.sqrt(), abs=1e-5)


def test_temperature_sharpens_the_sampled_policy_and_keeps_the_greedy_one():
    """softmax(logits / τ): below 1 the likely behavior gains, the greedy choice is the same, and the params the
    roll-out stores (for PPO's KL) are the tempered distribution's; the actor built from a config with it
    loads a τ = 1 actor's weights (the ``il`` initialisation)."""
    logits = torch.randn(6, 5, generator=torch.Generator().manual_seed(3))
    cool, plain = CategoricalDistribution(temperature=0.5), CategoricalDistribution()
    cool.update(logits)
    plain.update(logits)
    assert cool.probs == pytest.approx(Categorical(logits=2 * logits).probs)
    top = logits.argmax(-1, keepdim=True)
    assert (cool.probs.gather(1, top) > plain.probs.gather(1, top)).all() and (cool.entropy < plain.entropy).all()
    assert torch.equal(cool.deterministic_output(logits), plain.deterministic_output(logits))
    assert cool.kl_divergence(cool.params, plain.params) == pytest.approx(
        torch.distributions.kl_divergence(Categorical(logits=2 * logits), Categorical(logits=logits)), rel=1e-5)
    sharp, wide = torch.tensor([[0.0, -60.0, -120.0, 0.0, 0.0]]), torch.tensor([[0.0, -40.0, -50.0, 0.0, 0.0]])
    cool.update(sharp)  # exp(-240) underflows in float32: torch's categorical KL would be inf
    kl = cool.kl_divergence((wide,), cool.params)
    assert torch.isfinite(kl).all() and kl.item() > 0
    with pytest.raises(ValueError, match="temperature"):
        CategoricalDistribution(temperature=0.0)
    with pytest.raises(ValueError, match="temperature"):
        PPOConfig(temperature=-1.0)
    assert "temperature" not in behavior_model_cfgs()[0]["distribution_cfg"]  # the paper's configs as recorded
    warm = build_model(behavior_model_cfgs(temperature=0.5)[0], SHAPES, GROUPS, "actor", 1)
    warm.load_state_dict(build_model(behavior_model_cfgs()[0], SHAPES, GROUPS, "actor", 1).state_dict())
    assert warm.distribution.temperature == 0.5


def test_categorical_rejects_a_vector_action():
    with pytest.raises(ValueError, match="output_dim must be 1"):
        CategoricalDistribution(output_dim=2)


def test_network_has_the_papers_branches_and_starts_near_uniform():
    actor_cfg, critic_cfg = behavior_model_cfgs()
    actor = build_model(actor_cfg, SHAPES, GROUPS, "actor", 1)
    critic = build_model(critic_cfg, SHAPES, GROUPS, "critic", 1)
    convs = [m for m in actor.grid_encoders["occupancy"].modules() if isinstance(m, torch.nn.Conv2d)]
    assert len(convs) == 3, "M_t branch: three convolutions"
    assert isinstance(actor.grid_encoders["occupancy"][1], torch.nn.Linear), "... and one FC"
    assert actor.vector_encoder is not None and actor.obs_groups == ["road"], "R_t branch: FCs"
    obs = _random_obs(16)
    logits = actor.distribution_input(obs)
    assert logits.shape == (16, 5)
    assert torch.allclose(torch.softmax(logits, -1), torch.full((16, 5), 0.2), atol=0.02)
    assert actor(obs).shape == (16, 1) and actor(obs, stochastic_output=True).shape == (16, 1)
    assert critic(obs).shape == (16, 1)
    assert critic.distribution is None


def test_action_mask_removes_infeasible_behaviors():
    actor_cfg, _ = behavior_model_cfgs(mask_actions=True)
    actor = build_model(actor_cfg, SHAPES, GROUPS, "actor", 1)
    obs = _random_obs(64)
    obs["action_mask"][:, 2] = 0.0  # no left lane
    obs["action_mask"][:32, 3] = 0.0  # no right lane for half of them
    samples = actor(obs, stochastic_output=True).squeeze(-1)
    assert not (samples == 2).any() and not (samples[:32] == 3).any()
    probs = actor.distribution.probs
    assert probs[:, 2].max() == 0.0 and probs[:32, 3].max() == 0.0
    assert torch.isfinite(actor.output_entropy).all()
    with pytest.raises(ValueError, match="cannot also be a network input"):
        build_model(actor_cfg, SHAPES, {"actor": ["occupancy", "road", "action_mask"]}, "actor", 1)


def _ppo_round(actor_cfg, critic_cfg, num_actions, reward_fn):
    obs = _random_obs(4)
    storage = RolloutStorage("rl", 4, 16, obs, [num_actions])
    actor = build_model(actor_cfg, SHAPES, GROUPS, "actor", num_actions)
    critic = build_model(critic_cfg, SHAPES, GROUPS, "critic", 1)
    alg = TwoRatePPO(actor, critic, storage, actor_learning_rate=1e-4, critic_learning_rate=5e-4,
                     num_mini_batches=2, num_learning_epochs=2)
    before = ([p.clone() for p in actor.parameters()], [p.clone() for p in critic.parameters()])
    for step in range(16):
        step_obs = _random_obs(4, seed=step)
        actions = alg.act(step_obs)
        dones = torch.zeros(4, dtype=torch.long)
        alg.process_env_step(step_obs, reward_fn(actions), dones, {"time_outs": torch.zeros(4)})
    alg.compute_returns(_random_obs(4, seed=99))
    losses = alg.update()
    return alg, before, losses


def test_two_rate_ppo_updates_actor_and_critic_at_their_own_rates():
    actor_cfg, critic_cfg = behavior_model_cfgs()
    alg, (actor_before, critic_before), losses = _ppo_round(
        actor_cfg, critic_cfg, 1, lambda a: (a.squeeze(-1) == 4).float())
    lrs = [g["lr"] for g in alg.optimizer.param_groups]
    assert lrs == [1e-4, 5e-4]
    assert {id(p) for p in alg.optimizer.param_groups[0]["params"]} == {id(p) for p in alg.actor.parameters()}
    assert any(not torch.equal(a, b) for a, b in zip(actor_before, alg.actor.parameters())), "policy changed"
    assert any(not torch.equal(a, b) for a, b in zip(critic_before, alg.critic.parameters())), "value changed"
    assert all(torch.isfinite(torch.tensor(v)) for v in losses.values())


def test_flat_baseline_gaussian_controls_train_with_the_same_network():
    actor_cfg, critic_cfg = control_model_cfgs(init_std=0.5)
    alg, (actor_before, _), _ = _ppo_round(actor_cfg, critic_cfg, 2, lambda a: -a.pow(2).sum(-1))
    assert isinstance(alg.actor, BehaviorNetwork)
    assert alg.actor(_random_obs(3)).shape == (3, 2)
    assert any(not torch.equal(a, b) for a, b in zip(actor_before, alg.actor.parameters()))


def test_ppo_config_defaults_are_the_papers_and_validate():
    cfg = PPOConfig()
    assert (cfg.mini_batch_size, cfg.actor_learning_rate, cfg.critic_learning_rate, cfg.clip_param, cfg.gamma) == \
        (32, 1e-4, 5e-4, 0.2, 0.99)
    runner = cfg.runner_cfg(2, GROUPS, *behavior_model_cfgs())
    assert runner["algorithm"]["num_mini_batches"] * cfg.mini_batch_size == 2 * cfg.num_steps_per_env
    with pytest.raises(ValueError, match="multiple of the mini-batch"):
        PPOConfig(num_steps_per_env=10).runner_cfg(1, GROUPS, *behavior_model_cfgs())
    with pytest.raises(ValueError, match=r"slots \(workers × agents\) × num_steps_per_env = 2 × 64 = 128"):
        PPOConfig(mini_batch_size=256).runner_cfg(2, GROUPS, *behavior_model_cfgs())
    with pytest.raises(ValueError, match="schedule"):
        TwoRatePPO(None, None, None, schedule="adaptive")


def test_csv_log_drops_rows_logged_after_the_resumed_checkpoint(tmp_path):
    from hbmp_bench.training.runlog import CsvLog, read_csv

    path = str(tmp_path / "episodes.csv")
    with CsvLog(path, ("episode", "r_T")) as log:
        for k in range(1, 6):
            log.write({"episode": k, "r_T": float(k)})
    with CsvLog(path, ("episode", "r_T"), keep_through=3) as log:  # resumed from episode 3
        log.write({"episode": 4, "r_T": 40.0})
    rows = read_csv(path)
    assert rows["episode"].tolist() == [1, 2, 3, 4] and rows["r_T"].tolist() == [1.0, 2.0, 3.0, 40.0]


def test_ppo_from_an_imitated_control_actor_explores_with_the_runs_init_std():
    """flat-il fits only the mean of its Gaussian (its std is the one it was built with): PPO from it (flat-ilrl)
    starts at ``PPOConfig.init_std``, every other weight as imitated; a behavior actor is left as it is."""
    import math

    from hbmp_bench.agents.learned import shipped_checkpoint
    from hbmp_bench.policies.checkpoints import load_checkpoint
    from hbmp_bench.training.ppo import with_initial_std

    flat_il = load_checkpoint(shipped_checkpoint("flat-il"))
    narrow = with_initial_std(flat_il, 0.1)
    std = narrow["actor_state_dict"]["distribution.log_std_param"].exp()
    assert torch.allclose(std, torch.full_like(std, 0.1))
    assert flat_il["actor_state_dict"]["distribution.log_std_param"].exp().tolist() == pytest.approx([0.5, 0.5])
    kept = [k for k in flat_il["actor_state_dict"] if k != "distribution.log_std_param"]
    assert kept and all(narrow["actor_state_dict"][k] is flat_il["actor_state_dict"][k] for k in kept)
    model = build_model(narrow["model"]["actor"], {"occupancy": (1, 64, 36), "road": (12,)}, GROUPS, "actor", 2)
    model.load_state_dict(narrow["actor_state_dict"])
    assert math.isclose(float(model.distribution.log_std_param.detach()[0]), math.log(0.1), rel_tol=1e-6)
    for learnt in ("il", "flat"):  # a behavior actor; a PPO actor's std was learnt: both kept
        ckpt = load_checkpoint(shipped_checkpoint(learnt))
        assert with_initial_std(ckpt, 0.1) is ckpt
