"""``hbmp-bench train`` end to end on short Town02 routes in event fidelity: il, then hbmp from it,
hbmp-s from scratch; outputs, weights_only checkpoints that act, resume, and clear errors."""

import os

import pytest
import torch

from hbmp_bench.agents import load_agent
from hbmp_bench.cli import main
from hbmp_bench.envs import make
from hbmp_bench.locks import exclusive_lock
from hbmp_bench.training.commands import TrainingRunning
from hbmp_bench.training.runlog import EPISODE_COLUMNS, comparison_figure, comparison_series, read_csv

SCENARIO = "hbmp_bench/Town02-Straight-v0"
COMMON = ["--scenario", SCENARIO, "--seed", "0", "--no-progress", "--fidelity", "event"]

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def il_run(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("train") / "il")
    assert main(["train", "il", "--episodes", "2", "--workers", "2", "--out", out, *COMMON]) == 0
    return out


def _acts(policy_path):
    agent = load_agent(policy_path)
    env = make(SCENARIO, fidelity="event")
    try:
        obs, info = env.reset(seed=0, options={"episode_index": 0})
        agent.reset(info)
        for _ in range(5):
            action = agent.act(obs, info)
            assert isinstance(action, int) and 0 <= action < 5
            obs, _, terminated, truncated, info = env.step(action)
            assert not (terminated or truncated)
    finally:
        env.close()


def _files_of_a_run(out, episodes):
    for name in ("episodes.csv", "checkpoint.pt", "policy.pt", "curves.png", "MODEL_CARD.md"):
        assert os.path.isfile(os.path.join(out, name)), name
    with open(os.path.join(out, "curves.png"), "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    eps = read_csv(os.path.join(out, "episodes.csv"))
    assert set(EPISODE_COLUMNS) <= set(eps) and eps["episode"].tolist() == list(range(1, episodes + 1))
    assert (eps["length"] > 0).all() and set(eps["success"]) <= {0.0, 1.0}
    card = open(os.path.join(out, "MODEL_CARD.md")).read()
    for needle in ("hbmp-bench train", "seed: 0", f"episodes: {episodes}", "wall time", "machine"):
        assert needle in card
    return eps


def test_il_run_writes_log_checkpoint_curves_and_card(il_run):
    eps = _files_of_a_run(il_run, 2)
    assert "beta" in eps and "expert_share" in eps
    assert os.path.isfile(os.path.join(il_run, "rounds.csv")) and os.path.isfile(os.path.join(il_run, "dataset.npz"))
    ckpt = torch.load(os.path.join(il_run, "policy.pt"), weights_only=True)
    assert ckpt["kind"] == "il" and "optimizer_state_dict" not in ckpt
    assert torch.load(os.path.join(il_run, "checkpoint.pt"), weights_only=True)["optimizer_state_dict"]
    _acts(os.path.join(il_run, "policy.pt"))


def test_hbmp_from_il_warms_up_the_critic_learns_and_resumes(il_run, tmp_path):
    out = str(tmp_path / "hbmp")
    il_policy = os.path.join(il_run, "policy.pt")
    assert main(["train", "hbmp", "--episodes", "2", "--workers", "1", "--out", out, "--init", il_policy,
                 "--critic-warmup", "2", "--ppo", "entropy_coef=0.002", "--ppo", "anchor_coef=0.5",
                 "--ppo", "desired_kl=0.01", "--ppo", "anchor_kl=reverse", *COMMON]) == 0
    _files_of_a_run(out, 2)
    first = torch.load(os.path.join(out, "checkpoint.pt"), weights_only=True)
    il = torch.load(il_policy, weights_only=True)
    assert first["kind"] == "hbmp" and first["train"]["reward"] == "dense" and first["train"]["init"] == il_policy
    assert first["train"]["ppo.critic_warmup_episodes"] == 2 and first["train"]["ppo.entropy_coef"] == 0.002
    assert first["train"]["ppo.anchor_coef"] == 0.5 and first["train"]["ppo.desired_kl"] == 0.01
    assert first["train"]["ppo.anchor_kl"] == "reverse"
    assert "--ppo entropy_coef=0.002 --ppo anchor_coef=0.5" in open(os.path.join(out, "MODEL_CARD.md")).read()
    assert all(torch.equal(il["actor_state_dict"][k], v) for k, v in first["anchor_state_dict"].items()), \
        "the anchor is the --init actor, kept in the checkpoint for a resume"
    assert "optimizer_state_dict" not in first, "a PPO checkpoint is small enough to commit: no Adam moments"
    assert all(torch.equal(il["actor_state_dict"][k], v) for k, v in first["actor_state_dict"].items()), \
        "during the critic warm-up the IL actor does not move"
    iterations = read_csv(os.path.join(out, "iterations.csv"))
    assert iterations["iteration"].tolist() == list(range(1, first["progress"]["iterations"] + 1))
    assert (iterations["actor_frozen"] == 1).all() and iterations["value"].max() > 0, "the critic learns"
    assert (abs(iterations["kl_init"]) < 1e-6).all(), "a frozen actor is the IL actor"
    assert (iterations["actor_lr"] == 1e-4).all(), "the adaptive rate waits for the warm-up's end"
    _acts(os.path.join(out, "policy.pt"))

    # the resume keeps the recorded warm-up (2 episodes, over): the actor learns from episode 3 on
    assert main(["train", "hbmp", "--episodes", "3", "--workers", "1", "--out", out,
                 "--resume", os.path.join(out, "checkpoint.pt"), *COMMON]) == 0
    second = torch.load(os.path.join(out, "checkpoint.pt"), weights_only=True)
    assert second["progress"]["episodes"] == 3 and second["progress"]["iterations"] > first["progress"]["iterations"]
    assert second["train"]["ppo.critic_warmup_episodes"] == 2 and second["train"]["ppo.entropy_coef"] == 0.002
    assert read_csv(os.path.join(out, "episodes.csv"))["episode"].tolist() == [1, 2, 3]
    assert any(not torch.equal(first["actor_state_dict"][k], v) for k, v in second["actor_state_dict"].items()), \
        "PPO changed the IL-initialised policy after the warm-up"
    assert any(not torch.equal(first["critic_state_dict"][k], v) for k, v in second["critic_state_dict"].items()), \
        "the value network kept learning after the resume"
    iterations = read_csv(os.path.join(out, "iterations.csv"))
    assert iterations["iteration"].tolist() == list(range(1, second["progress"]["iterations"] + 1))
    assert iterations["actor_frozen"][-1] == 0
    assert iterations["kl_init"][-1] > 0 and iterations["actor_lr"][-1] != 1e-4, \
        "after the warm-up the actor moves away from the anchor at an adapted rate"
    assert all(torch.equal(il["actor_state_dict"][k], v) for k, v in second["anchor_state_dict"].items())

    assert main(["curves", il_run, out, "--labels", "il", "hbmp", "--out", str(tmp_path / "fig.png")]) == 0
    assert os.path.getsize(tmp_path / "fig.png") > 1000


def test_hbmp_s_from_random_init_uses_the_sparse_reward(tmp_path):
    out = str(tmp_path / "hbmp-s")
    assert main(["train", "hbmp-s", "--episodes", "1", "--workers", "1", "--out", out, "--init", "none",
                 *COMMON]) == 0
    ckpt = torch.load(os.path.join(out, "policy.pt"), weights_only=True)
    assert ckpt["kind"] == "hbmp-s" and ckpt["train"]["reward"] == "sparse" and ckpt["train"]["init"] is None
    eps = read_csv(os.path.join(out, "episodes.csv"))
    assert eps["train_return"][0] == pytest.approx(0.01 * eps["r_T"][0], abs=1e-3), "scaled r_T only"


def test_clear_errors(il_run, tmp_path, capsys):
    assert main(["train", "hbmp", "--resume", os.path.join(il_run, "checkpoint.pt"), "--out", str(tmp_path),
                 *COMMON]) == 2
    assert "'il' policy" in capsys.readouterr().err
    assert main(["train", "hbmp", "--init", str(tmp_path / "missing.pt"), "--out", str(tmp_path), *COMMON]) == 2
    assert "no checkpoint file" in capsys.readouterr().err
    assert main(["train", "il", "--scenario", "hbmp_bench/Town9-Straight-v0", "--out", str(tmp_path)]) == 2
    assert "Town01-Straight-v0" in capsys.readouterr().err
    assert main(["train", "flat", "--fidelity", "event", "--out", str(tmp_path / "flat"), "--episodes", "1"]) == 2
    assert "continuous" in capsys.readouterr().err
    assert main(["train", "hbmp", "--reward", "carla", "--out", str(tmp_path / "x"), *COMMON]) == 2
    assert "--reward" in capsys.readouterr().err and not os.path.exists(tmp_path / "x")
    assert main(["train", "hbmp", "--ppo", "entropy=0.1", "--out", str(tmp_path / "x"), *COMMON]) == 2
    assert "entropy_coef" in capsys.readouterr().err and not os.path.exists(tmp_path / "x")
    assert main(["train", "hbmp", "--ppo", "anchor_coef=lots", "--out", str(tmp_path / "x"), *COMMON]) == 2
    assert "number" in capsys.readouterr().err
    assert main(["train", "hbmp", "--ppo", "anchor_kl=sideways", "--out", str(tmp_path / "x"), *COMMON]) == 2
    assert "forward, reverse" in capsys.readouterr().err and not os.path.exists(tmp_path / "x")
    assert main(["train", "hbmp", "--ppo", "anchor_coef=1", "--init", "none", "--out", str(tmp_path / "x"),
                 *COMMON]) == 2
    assert "--init" in capsys.readouterr().err
    assert main(["train", "hbmp", "--critic-warmup", "5", "--ppo", "critic_warmup_episodes=7", "--out",
                 str(tmp_path / "x"), *COMMON]) == 2
    assert "disagree" in capsys.readouterr().err and not os.path.exists(tmp_path / "x")
    assert main(["train", "hbmp", "--ppo", "anchor_coef=1", "--resume", os.path.join(il_run, "checkpoint.pt"),
                 "--out", str(tmp_path / "x"), *COMMON]) == 2
    assert "recorded" in capsys.readouterr().err
    # an il checkpoint as flat's --init: refused by the trainer, after the run folder was made; not left behind
    assert main(["train", "flat", "--init", os.path.join(il_run, "policy.pt"), "--out", str(tmp_path / "x"),
                 *COMMON[:-2]]) == 2
    assert "flat" in capsys.readouterr().err and not os.path.exists(tmp_path / "x")
    busy = tmp_path / "busy"
    busy.mkdir()
    with exclusive_lock(busy / "train.lock", TrainingRunning):  # a run already writing that folder
        assert main(["train", "hbmp", "--episodes", "1", "--out", str(busy), *COMMON]) == 2
    assert f"pid {os.getpid()}" in capsys.readouterr().err and os.listdir(busy) == ["train.lock"]


def test_flat_trains_on_the_control_env_and_is_evaluated_there(tmp_path):
    """The flat baseline: PPO on [accel, steer], here on CARLA's RL reward (``--reward carla``, which the
    checkpoint records for a resume; the log keeps the paper's r_T beside it); the evaluation builds the env its
    policy asks for."""
    from hbmp_bench.evaluation import evaluate
    from hbmp_bench.training.commands import RUN_OPTIONS, recorded_env_options

    out = str(tmp_path / "flat")
    assert main(["train", "flat", "--episodes", "1", "--workers", "1", "--out", out, "--scenario", SCENARIO,
                 "--seed", "0", "--no-progress", "--reward", "carla"]) == 0
    row = {name: column[0] for name, column in _files_of_a_run(out, 1).items()}
    assert recorded_env_options(os.path.join(out, "checkpoint.pt"), RUN_OPTIONS)["reward"] == "carla"
    # the paper's r_T of how it ended is logged (no r_t beside it); the run learnt from another reward
    assert row["r_T"] == row["r_T_plus_r_t"] and (row["r_T"] <= -50.0 or row["r_T"] == 100.0)
    assert row["train_return"] != pytest.approx(0.01 * row["r_T"])
    policy = os.path.join(out, "policy.pt")
    agent = load_agent(policy)
    assert not agent.discrete and agent.env_factory.endswith("control_env:ControlEnv")
    result = evaluate("corl2017", policy, towns=["Town02"], tasks=["Straight"], episodes=1, workers=1,
                      out_dir=tmp_path / "eval", progress=False)
    (record,) = result.records
    assert record.end_reason not in ("agent_error", "sim_error"), record.error
    assert record.decisions > 0


def test_metric_road_profile_travels_from_training_to_evaluation(tmp_path):
    """An il run on the metric R_t records it; its checkpoint asks the evaluator for it (and gets 12 entries)."""
    from hbmp_bench.evaluation import evaluate

    out = str(tmp_path / "il-metric")
    assert main(["train", "il", "--episodes", "1", "--workers", "1", "--out", out, "--road-profile", "metric",
                 *COMMON]) == 0
    policy = os.path.join(out, "policy.pt")
    ckpt = torch.load(policy, weights_only=True)
    assert ckpt["model"]["obs_shapes"]["road"] == [12] and ckpt["model"]["env"]["road_profile"] == "metric"
    agent = load_agent(policy)
    assert agent.env_kwargs == {"road_profile": "metric"}
    result = evaluate("corl2017", policy, towns=["Town02"], tasks=["Straight"], episodes=1, workers=1,
                      fidelity="event", out_dir=tmp_path / "eval", progress=False)
    (record,) = result.records
    assert record.end_reason not in ("agent_error", "sim_error"), record.error
    assert record.decisions > 0

    # PPO from it takes the metric R_t from the checkpoint (no --road-profile given), and so does its resume
    hbmp = str(tmp_path / "hbmp")
    assert main(["train", "hbmp", "--episodes", "1", "--workers", "1", "--out", hbmp, "--init", policy,
                 "--critic-warmup", "0", "--save-every", "1", *COMMON]) == 0
    assert main(["train", "hbmp", "--episodes", "2", "--workers", "1", "--out", hbmp,
                 "--resume", os.path.join(hbmp, "checkpoint.pt"), *COMMON]) == 0
    ckpt = torch.load(os.path.join(hbmp, "checkpoint.pt"), weights_only=True)
    assert ckpt["model"]["env"]["road_profile"] == "metric" and ckpt["progress"]["episodes"] == 2
    assert "--road-profile metric" in open(os.path.join(hbmp, "MODEL_CARD.md")).read()


def test_validation_rows_and_best_policy(il_run, tmp_path):
    """--validate-every: the initial actor first, then the greedy policy every N episodes on hbmp-val;
    best.pt is the best row's actor (success, then route completion; ties: the later one) and acts; a resume keeps
    the rows before it."""
    out = str(tmp_path / "hbmp-val")
    il_policy = os.path.join(il_run, "policy.pt")
    assert main(["train", "hbmp", "--episodes", "2", "--workers", "1", "--out", out, "--init", il_policy,
                 "--critic-warmup", "0", "--validate-every", "2", "--validate-episodes", "1", *COMMON]) == 0
    rows = read_csv(os.path.join(out, "validation.csv"))
    assert rows["episode"][0] == 0 and rows["episode"][-1] >= 2 and len(rows["episode"]) == 2
    assert (rows["episodes"] == 2).all(), "the first episode of each of hbmp-val's two tasks"
    assert ((rows["success"] >= 0) & (rows["success"] <= 1)).all()
    assert (rows["route_completion"] > 0).all() and (rows["wall_s"] > 0).all()
    best = torch.load(os.path.join(out, "best.pt"), weights_only=True)
    assert set(best) >= {"kind", "model", "actor_state_dict"} and "critic_state_dict" not in best
    final = torch.load(os.path.join(out, "policy.pt"), weights_only=True)
    il = torch.load(il_policy, weights_only=True)
    later_ranks = (rows["success"][1], rows["route_completion"][1]) >= (rows["success"][0], rows["route_completion"][0])
    chosen = final if later_ranks else il
    assert all(torch.equal(chosen["actor_state_dict"][k], v) for k, v in best["actor_state_dict"].items())
    _acts(os.path.join(out, "best.pt"))
    card = open(os.path.join(out, "MODEL_CARD.md")).read()
    assert f"greedy success on hbmp-val, first: {rows['success'][0]:.1%} at episode 0" in card

    assert main(["train", "hbmp", "--episodes", "3", "--workers", "1", "--out", out, "--validate-every", "2",
                 "--validate-episodes", "1", "--resume", os.path.join(out, "checkpoint.pt"), *COMMON]) == 0
    again = read_csv(os.path.join(out, "validation.csv"))
    assert again["episode"].tolist()[:2] == rows["episode"].tolist(), "rows up to the checkpoint are kept"


def test_validation_ranks_success_then_route_completion(tmp_path):
    """best.pt's choice among validations: success first; at equal success (e.g. none reach a goal) the one that
    drove further; at an equal rank the later one. The model card names the same row."""
    from hbmp_bench.training.validation import VALIDATION_COLUMNS, validation_rank, validation_results

    assert validation_rank(0.5, 0.1) > validation_rank(0.45, 0.9)
    assert validation_rank(0.0, 0.15) > validation_rank(0.0, 0.14)
    def best_of(rows):
        with open(tmp_path / "validation.csv", "w") as f:
            f.write(",".join(VALIDATION_COLUMNS) + "\n")
            for episode, success, completion in rows:
                f.write(f"{episode},{success},{success},{success},{completion},0,0,0,0,20,1.0\n")
        return validation_results(str(tmp_path))["greedy success on hbmp-val, best (best.pt)"]

    rows = [(0, 0.0, 0.10), (500, 0.0, 0.15), (1000, 0.0, 0.12)]
    assert best_of(rows) == "0.0% at episode 500"
    assert best_of([*rows, (1500, 0.0, 0.15)]) == "0.0% at episode 1500"
    assert best_of([*rows, (1500, 0.05, 0.01)]) == "5.0% at episode 1500"


def test_validation_needs_no_sandbox(il_run, monkeypatch):
    """The run validates its own actor, trusted: on a host without bubblewrap a run with --validate-every
    trains (it stopped at episode 0 with the sandbox's error), while a submitted checkpoint is still refused."""
    from hbmp_bench.evaluation import Job, run_jobs
    from hbmp_bench.evaluation import pool
    from hbmp_bench.evaluation.namespaces import SandboxUnavailable
    from hbmp_bench.training.validation import validate

    monkeypatch.setattr(pool, "sandbox_problem", lambda: "bwrap (bubblewrap) is not installed")
    policy = os.path.join(il_run, "policy.pt")
    with pytest.raises(SandboxUnavailable, match="bubblewrap"):
        run_jobs([Job("hbmp-val", "Town03", "Navigation", policy, (0,), "event")], workers=1, progress=False)
    row = validate(policy, workers=1, fidelity="event", episodes=1)
    assert row["episodes"] == 2 and 0 <= row["success"] <= 1 and row["route_completion"] > 0


def test_validate_every_is_for_ppo(tmp_path, capsys):
    assert main(["train", "il", "--validate-every", "5", "--out", str(tmp_path / "il"), *COMMON]) == 2
    assert "--validate-every" in capsys.readouterr().err and not os.path.exists(tmp_path / "il")


def test_the_resume_hint_is_a_command_train_accepts(tmp_path):
    """An interrupted PPO run prints how to continue: without what a resume refuses (--ppo) or ignores (--init,
    --critic-warmup: the checkpoint recorded them), with the save and validation cadence it ran with."""
    import shlex

    from hbmp_bench.cli import build_parser
    from hbmp_bench.policies.checkpoints import save_checkpoint
    from hbmp_bench.training.commands import _resume_hint

    out = tmp_path / "run"
    argv = ["train", "hbmp", "--out", str(out), "--episodes", "3000", "--init", "il", "--ppo", "anchor_coef=0.1",
            "--critic-warmup", "50", "--validate-every", "100", "--save-every", "25"]
    save_checkpoint(str(out / "checkpoint.pt"),
                    {"kind": "hbmp", "progress": {"episodes": 10, "decisions": 1, "iterations": 1, "wall_s": 1.0}})
    hint = _resume_hint(build_parser().parse_args(argv))
    assert "(10 of 3000 episodes)" in hint
    command = shlex.split(hint.split("resume with: ")[1])
    assert not {"--ppo", "--init", "--critic-warmup"} & set(command)
    assert command[command.index("--resume") + 1] == str(out / "checkpoint.pt")
    assert command[command.index("--validate-every") + 1] == "100" and command[command.index("--save-every") + 1] == "25"
    build_parser().parse_args(command[1:])


def test_ppo_names_the_fields_of_the_dedicated_flags():
    """``--ppo critic_warmup_episodes=N`` and ``--ppo mask_actions=true`` set what ``--critic-warmup`` and
    ``--mask-actions`` set (it used to be a TypeError); agreeing pairs are fine."""
    from hbmp_bench.cli import build_parser
    from hbmp_bench.training.commands import _ppo_config

    def config(*argv):
        return _ppo_config(build_parser().parse_args(["train", "hbmp", *argv]), "il")

    assert config("--ppo", "critic_warmup_episodes=7").critic_warmup_episodes == 7
    assert config("--critic-warmup", "3").critic_warmup_episodes == 3
    assert config("--ppo", "mask_actions=true").mask_actions
    assert config("--mask-actions", "--ppo", "mask_actions=true").mask_actions
    assert config().critic_warmup_episodes > 0 and _ppo_config(
        build_parser().parse_args(["train", "hbmp"]), None).critic_warmup_episodes == 0


def _write_csv(folder, name, columns, rows):
    """``folder/name`` with ``columns`` and one line per dict of ``rows`` (0 where a row has no value); its path."""
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, name)
    with open(path, "w") as f:
        f.write(",".join(columns) + "\n")
        for values in rows:
            f.write(",".join(str(values.get(c, 0)) for c in columns) + "\n")
    return path


def test_the_ablation_figure_shows_a_run_that_learns_to_stand(tmp_path):
    """The comparison figure's timeout panel: the share of episodes ending at the timeout, trailing."""
    rows = [(1, "violation", 0), (2, "goal", 1), (3, "timeout", 0), (4, "timeout", 0)]
    path = _write_csv(str(tmp_path), "episodes.csv", EPISODE_COLUMNS,
                      [{"episode": e, "end_reason": reason, "success": success, "r_T": -1, "r_T_plus_r_t": -2}
                       for e, reason, success in rows])
    series = comparison_series(read_csv(path), window=2)
    assert list(series) == ["r_T", "r_T_plus_r_t", "success", "timeout"]
    assert series["timeout"].tolist() == [0.0, 0.0, 0.5, 1.0]
    assert series["success"].tolist() == [0.0, 0.5, 0.5, 0.0]


def test_the_comparison_figure_shows_greedy_validations_with_their_noise(tmp_path):
    """A run with a ``validation.csv`` adds a panel of its greedy validations (one point per validation, a band of
    one binomial standard error over its episodes); runs without one are left out of it, and a figure of runs
    that have none keeps the four panels."""
    import matplotlib.pyplot as plt

    from hbmp_bench.training.validation import VALIDATION_COLUMNS

    plain, validated = str(tmp_path / "plain"), str(tmp_path / "validated")
    for folder in (plain, validated):
        _write_csv(folder, "episodes.csv", EPISODE_COLUMNS,
                   [{"episode": e, "end_reason": "goal", "success": 1} for e in range(1, 5)])
    _write_csv(validated, "validation.csv", VALIDATION_COLUMNS,
               [{"episode": e, "success": success, "episodes": 40} for e, success in ((0, 0.925), (200, 0.9), (400, 1.0))])
    fig = comparison_figure([plain, validated], ["plain", "validated"], window=2)
    panel = fig.axes[-1]
    assert len(fig.axes) == 5 and "validation" in panel.get_ylabel()
    (line,) = panel.get_lines()  # the plain run has no validations
    assert line.get_xdata().tolist() == [0, 200, 400] and line.get_ydata().tolist() == [0.925, 0.9, 1.0]
    (band,) = panel.collections
    low = band.get_paths()[0].vertices[:, 1].min()
    assert abs(low - (0.9 - (0.9 * 0.1 / 40) ** 0.5)) < 1e-9  # 40 episodes at 90 %: +- 4.7 points
    plain_fig = comparison_figure([plain], ["plain"], window=2)
    assert len(plain_fig.axes) == 4
    plt.close(fig)
    plt.close(plain_fig)


def test_many_learners_are_recorded_and_a_resume_keeps_them(tmp_path):
    """``--agents 2``: four slots from two workers; the checkpoint and the model card's command name the learners,
    so a resume that does not repeat the flag trains with them again (not a single ego)."""
    out = str(tmp_path / "hbmp-agents")
    options = ["--seed", "0", "--no-progress", "--fidelity", "event", "--init", "none", "--workers", "2"]
    assert main(["train", "hbmp", "--episodes", "2", "--agents", "2", "--out", out, "--save-every", "1",
                 *options]) == 0
    ckpt = torch.load(os.path.join(out, "checkpoint.pt"), weights_only=True)
    assert ckpt["model"]["env"]["agents"] == 2 and ckpt["progress"]["episodes"] >= 2
    assert "--agents 2" in ckpt["train"]["command"]
    more = str(ckpt["progress"]["episodes"] + 1)
    assert main(["train", "hbmp", "--episodes", more, "--out", out, "--resume", os.path.join(out, "checkpoint.pt"),
                 "--no-progress"]) == 0
    resumed = torch.load(os.path.join(out, "checkpoint.pt"), weights_only=True)
    assert resumed["model"]["env"]["agents"] == 2
    decisions = read_csv(os.path.join(out, "iterations.csv"))["decisions"].tolist()
    per_iteration = [b - a for a, b in zip([0] + decisions[:-1], decisions)]
    assert len(per_iteration) >= 2 and set(per_iteration) == {64 * 2 * 2}  # 64 steps x 2 workers x 2 slots, resumed too
    card = open(os.path.join(out, "MODEL_CARD.md")).read()
    assert "--agents 2" in card and "learners: 2 per simulation x 2 workers = 4 slots" in card


@pytest.mark.parametrize("kind", ["hbmp", "flat"])
def test_overlapped_updates_train_and_a_seed_gives_the_same_run(tmp_path, kind):
    """``--agents 2`` with ``--ppo overlap_update=true``: the update runs beside the next roll-out, for learners
    that decide when their behaviors end (hbmp, continuous fidelity) and for learners that all decide every
    0.1 s (flat's controls); every iteration fills 2 slots x 8 decisions, and the same seed gives the same
    losses (the schedule does not depend on timing, the update thread draws no random number)."""
    runs = []
    for name in ("a", "b"):
        out = str(tmp_path / name)
        assert main(["train", kind, "--episodes", "4", "--agents", "2", "--workers", "1", "--out", out,
                     "--seed", "3", "--init", "none", "--no-progress", "--ppo", "overlap_update=true",
                     "--ppo", "num_steps_per_env=8", "--ppo", "mini_batch_size=8",
                     *(["--fidelity", "continuous"] if kind == "hbmp" else [])]) == 0
        runs.append(read_csv(os.path.join(out, "iterations.csv")))
    first, second = runs
    decisions = first["decisions"].tolist()
    assert len(decisions) >= 3 and {b - a for a, b in zip([0] + decisions[:-1], decisions)} == {16}
    for column in ("value", "surrogate", "entropy"):
        assert first[column].tolist() == second[column].tolist(), column
    assert "overlap_update=true" in open(os.path.join(tmp_path, "a", "MODEL_CARD.md")).read()
