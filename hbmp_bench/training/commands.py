"""``hbmp-bench train {il,hbmp,hbmp-s,flat,flat-il}`` and ``hbmp-bench curves``.

    hbmp-bench train il     --episodes N --workers W --seed S --out DIR   DAgger, event fidelity (the paper's;
                                                                          --fidelity continuous: the shipped il)
    hbmp-bench train hbmp   ... [--init il|CKPT|none]                     PPO, r_k + r_T, continuous fidelity
    hbmp-bench train hbmp-s ...                                           PPO, r_T only
    hbmp-bench train flat   ... [--init flat-il|CKPT|none]                PPO on acceleration and steering
    hbmp-bench train flat-il ...                                          DAgger on the expert's controls (CIL)
    hbmp-bench curves DIR [DIR ...] --labels ... --out fig.png             r_T and r_T + Σr_t of several runs

Ablations: ``--init none`` (random instead of IL initialisation), ``--road-profile metric`` (R_t with the stop
distance and speed in metres and m/s), ``--observation vehicle_centric``
(non-deformed M_t).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shlex
import shutil
import time

from hbmp_bench.errors import Interrupted, UserError
from hbmp_bench.locks import Busy, exclusive_lock
from hbmp_bench.policies.checkpoints import KINDS
from hbmp_bench.vocabulary import ENV_REWARDS

DEFAULT_EPISODES = {"il": 3000, "hbmp": 6000, "hbmp-s": 6000, "flat": 6000, "flat-il": 200}
"""Paper: 6000 RL episodes; DAgger's α starts decaying after 3000 (its IL budget is not given); flat-il: the
budget of its shipped run."""
DEFAULT_FIDELITY = {"il": "event", "hbmp": "continuous", "hbmp-s": "continuous", "flat": None, "flat-il": None}
REWARD = {"il": "dense", "hbmp": "dense", "hbmp-s": "sparse", "flat": "env", "flat-il": "env"}
DAGGER_KINDS = ("il", "flat-il")
"""The kinds DAgger trains (from the expert, from a random network); the others are PPO's."""
CONTROL_KINDS = ("flat", "flat-il")
"""The kinds that drive the control env (acceleration and steering, no behavior layer)."""
CONTROL_ENV = "hbmp_bench.envs.control_env:ControlEnv"
CRITIC_WARMUP_EPISODES = 100
"""Default critic warm-up of a PPO run that starts from an IL actor (none from a random one)."""
SAVE_EVERY = 50
"""Default checkpoint interval [episodes]."""


def _command_line(args: argparse.Namespace) -> str:
    """The command as a user would type it (for the model card)."""
    parts = ["hbmp-bench", "train", args.kind, "--scenario", args.scenario, "--episodes", str(args.episodes),
             "--workers", str(args.workers), "--seed", str(args.seed), "--out", args.out]
    for flag, value in (("--agents", str(args.agents) if (args.agents or 1) > 1 else None),
                        ("--fidelity", args.fidelity), ("--observation", args.observation),
                        ("--road-profile", args.road_profile), ("--density", args.density), ("--reward", args.reward),
                        ("--init", args.init), ("--resume", args.resume),
                        ("--critic-warmup", None if args.critic_warmup is None else str(args.critic_warmup)),
                        ("--backend", None if args.backend == "process" else args.backend),
                        ("--address", args.address)):
        if value is not None:
            parts += [flag, value]
    for assignment in args.ppo:
        parts += ["--ppo", assignment]
    if args.mask_actions:
        parts.append("--mask-actions")
    if args.save_every != SAVE_EVERY:
        parts += ["--save-every", str(args.save_every)]
    if args.validate_every:
        parts += ["--validate-every", str(args.validate_every)]
        if args.validate_episodes is not None:
            parts += ["--validate-episodes", str(args.validate_episodes)]
    return " ".join(shlex.quote(p) for p in parts)


def resolve_init(kind: str, init: str | None) -> str | None:
    """The checkpoint that initialises a PPO actor: a path, a shipped name, or None (random)."""
    if kind in DAGGER_KINDS:
        if init not in (None, "none"):
            raise UserError(f"--init does not apply to {kind} (DAgger starts from a random network)")
        return None
    if init is None:
        init = "il" if kind in ("hbmp", "hbmp-s") else "none"
    if init == "none":
        return None
    if kind == "flat" and not (init == "flat-il" or init.endswith(".pt")):
        raise UserError("the flat baseline starts from a control policy: --init flat-il, a flat-il checkpoint "
                        "(.pt) or none")
    if init.endswith(".pt"):
        if not os.path.isfile(init):
            raise FileNotFoundError(f"no checkpoint file {init!r}")
        return init
    from hbmp_bench.agents.learned import shipped_checkpoint

    return shipped_checkpoint(init)


INPUT_OPTIONS = ("observation", "road_profile")
"""Env options a PPO run takes from its ``--init`` checkpoint when the command does not give them: the network's
inputs must be what the initial actor was trained on."""
RUN_OPTIONS = ("fidelity", "observation", "road_profile", "density", "reward", "agents")
"""Env options a ``--resume`` takes from the checkpoint when the command does not give them: the run goes on as
it began."""


def recorded_env_options(checkpoint: str, names: tuple[str, ...]) -> dict[str, str]:
    """The env options ``names`` that ``checkpoint`` recorded (those it did not record are left out)."""
    from hbmp_bench.policies.checkpoints import load_checkpoint

    recorded = load_checkpoint(checkpoint).get("model", {}).get("env", {})
    return {k: recorded[k] for k in names if k in recorded}


class TrainingRunning(Busy):
    """Another training run holds the run folder's lock."""


def _cmd_train(args: argparse.Namespace) -> int:
    from hbmp_bench.training.run import RunConfig

    kind = args.kind
    if args.episodes is None:
        args.episodes = DEFAULT_EPISODES[kind]
    if args.out is None:
        args.out = os.path.join("runs", f"{kind}__{args.scenario.split('/')[-1]}__{args.seed}__{int(time.time())}")
    _check_kind_options(args)
    init = resolve_init(kind, args.init) if args.resume is None else None
    ppo = _ppo_config(args, init) if kind not in DAGGER_KINDS and args.resume is None else None  # a resume keeps its own
    env_config = _env_config(args, init)
    run = RunConfig(kind=kind, episodes=args.episodes, out=args.out, workers=args.workers, backend=args.backend,
                    address=args.address, seed=args.seed,
                    save_every=args.save_every, resume=args.resume, command=_command_line(args),
                    progress=not args.no_progress, validate_every=args.validate_every,
                    validate_episodes=args.validate_episodes)
    created = not os.path.exists(args.out)
    os.makedirs(args.out, exist_ok=True)
    try:
        with exclusive_lock(os.path.join(args.out, "train.lock"), lambda holder: TrainingRunning(
                f"another training run (pid {holder}) is writing {args.out}: wait for it, or train into another --out")):
            result = _train(kind, run, env_config, args, init, ppo)
    except KeyboardInterrupt:  # the trainer has closed its workers on the way out
        raise Interrupted(_resume_hint(args)) from None
    except Exception:
        if created:
            _remove_if_unwritten(args.out)
        raise
    p = result["progress"]
    print(f"trained {kind}: {p['episodes']} episodes, {p['decisions']} decisions, {p['wall_s'] / 60:.1f} min")
    print(f"run folder: {args.out}  (episodes.csv, curves.png, checkpoint.pt, MODEL_CARD.md)")
    print(f"policy: {result['policy']}  (evaluate: hbmp-bench run --agent {result['policy']})")
    return 0


def _remove_if_unwritten(out: str) -> None:
    """Remove the run folder this command created when the run stopped before writing anything but its lock
    (a refused option, a worker that failed to start): no empty run folder is left behind."""
    leftover = set(os.listdir(out)) - {"train.lock"}
    if not leftover:
        shutil.rmtree(out, ignore_errors=True)


def _check_kind_options(args: argparse.Namespace) -> None:
    """Refuse options the run's kind (or a resume) does not take, before anything is read or started."""
    if args.validate_every and args.kind == "il":
        raise UserError("--validate-every applies to hbmp, hbmp-s, flat and flat-il (DAgger's rounds.csv has "
                        "its holdout)")
    if args.ppo and args.kind in DAGGER_KINDS:
        raise UserError(f"--ppo options apply to hbmp, hbmp-s and flat ({args.kind} is trained by DAgger)")
    if args.mask_actions and args.kind in CONTROL_KINDS:
        raise UserError(f"--mask-actions masks behaviors; {args.kind} drives with controls")
    if args.reward is not None and args.kind != "flat":
        raise UserError(f"--reward chooses the control env's reward for flat; {args.kind}'s reward is its kind's")
    if args.ppo and args.resume:
        raise UserError("a resumed run keeps the PPO options its checkpoint recorded; start a new --out to change "
                        "them")


def _env_config(args: argparse.Namespace, init: str | None):
    """The workers' environment: the options given, else those the resumed (or ``--init``) checkpoint recorded
    (``RUN_OPTIONS`` / ``INPUT_OPTIONS``; written back into ``args`` so the model card's command has them), else
    the kind's defaults."""
    from hbmp_bench.training.worker import WorkerEnvConfig

    kind = args.kind
    source = (args.resume, RUN_OPTIONS) if args.resume else (init, INPUT_OPTIONS) if init else None
    for name, value in (recorded_env_options(*source) if source else {}).items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    if args.fidelity is None:
        args.fidelity = DEFAULT_FIDELITY[kind]
    args.agents = int(args.agents or 1)
    env_kwargs = {k: v for k, v in (("fidelity", args.fidelity), ("observation", args.observation),
                                    ("road_profile", args.road_profile), ("density", args.density),
                                    ("reward", args.reward))
                  if v is not None}
    entry_point = None
    if kind in CONTROL_KINDS:
        if importlib.util.find_spec(CONTROL_ENV.split(":")[0]) is None:
            raise UserError(f"train {kind} needs the continuous-control env hbmp_bench.envs.control_env.ControlEnv, "
                            "which this installation does not have yet")
        entry_point = CONTROL_ENV
    return WorkerEnvConfig(env_id=args.scenario, env_kwargs=env_kwargs, entry_point=entry_point, reward=REWARD[kind],
                           agents=args.agents)


def _ppo_config(args: argparse.Namespace, init: str | None):
    """The PPO options of a new run (defaults, ``--critic-warmup``, ``--mask-actions``, ``--ppo``), checked
    before any worker starts."""
    from hbmp_bench.training.ppo import PPOConfig

    assigned = PPOConfig.parse_assignments(args.ppo)
    flags = {"critic_warmup_episodes": ("--critic-warmup", args.critic_warmup),
             "mask_actions": ("--mask-actions", args.mask_actions or None)}
    for name, (flag, value) in flags.items():
        if value is not None and name in assigned and assigned[name] != value:
            raise UserError(f"{flag} and --ppo {name}= disagree ({value} against {assigned[name]}): give one")
    options = {"critic_warmup_episodes": CRITIC_WARMUP_EPISODES if init is not None else 0,
               **{name: value for name, (_, value) in flags.items() if value is not None}, **assigned}
    ppo = PPOConfig(**options)
    if ppo.anchor_coef > 0 and init is None:
        raise UserError("--ppo anchor_coef needs an --init actor to anchor to")
    return ppo


def _train(kind: str, run, env_config, args: argparse.Namespace, init: str | None, ppo) -> dict:
    """DAgger for il (behaviors) and flat-il (controls), PPO otherwise (``ppo``: None on a resume, which keeps
    the recorded options); the run's progress and the path of its policy."""
    if kind == "flat-il":
        from hbmp_bench.training.control_dagger import DaggerControlConfig, train_control_dagger

        return train_control_dagger(run, env_config, DaggerControlConfig())
    if kind == "il":
        from hbmp_bench.training.dagger import DaggerConfig, train_dagger

        return train_dagger(run, env_config, DaggerConfig(mask_actions=args.mask_actions))
    from hbmp_bench.training.ppo import train_ppo

    label = None if init is None else (args.init or ("flat-il" if kind == "flat" else "il"))
    return train_ppo(run, env_config, ppo, init=init, init_label=label)


def _resume_hint(args: argparse.Namespace) -> str:
    """What an interrupted ``train`` left and the command that continues it."""
    from hbmp_bench.policies.checkpoints import load_checkpoint

    checkpoint = os.path.join(args.out, "checkpoint.pt")
    if not os.path.isfile(checkpoint):
        return (f"no checkpoint was written yet (one every {args.save_every} episodes); "
                f"start over with another --out than {args.out}")
    done = load_checkpoint(checkpoint, kinds=(args.kind,))["progress"]["episodes"]
    if done >= args.episodes:
        return (f"all {done} episodes are trained ({checkpoint}); {os.path.join(args.out, 'policy.pt')}, "
                "the curves or the model card may be missing")
    # a resume keeps the initial actor, PPO options and warm-up its checkpoint recorded (and refuses --ppo)
    again = _command_line(argparse.Namespace(**{**vars(args), "resume": checkpoint, "init": None, "ppo": [],
                                                "critic_warmup": None}))
    return f"the last checkpoint is {checkpoint} ({done} of {args.episodes} episodes); resume with: {again}"


def _cmd_curves(args: argparse.Namespace) -> int:
    from hbmp_bench.training.runlog import plot_comparison

    labels = args.labels or [os.path.basename(os.path.normpath(d)) for d in args.runs]
    for folder in args.runs:
        if not os.path.isfile(os.path.join(folder, "episodes.csv")):
            raise FileNotFoundError(f"no episodes.csv in {folder!r}")
    print(plot_comparison(args.runs, labels, args.out, window=args.window))
    return 0


def add_commands(subparsers) -> None:
    """Add ``train`` and ``curves`` to the ``hbmp-bench`` parser."""
    p = subparsers.add_parser("train", help="train il or flat-il (DAgger), hbmp, hbmp-s or flat (PPO, rsl-rl)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("kind", choices=KINDS, help="what to train: " + ", ".join(KINDS))
    p.add_argument("--scenario", default="hbmp_bench/Training-v0", help="env id; hbmp_bench/Training-v0 is Town03 with a random start and goal every reset")
    p.add_argument("--episodes", type=int, default=None,
                   help="episode budget (default: il 3000, others 6000 as in the paper)")
    p.add_argument("--workers", type=int, default=2, help="environment processes (one SUMO each)")
    p.add_argument("--agents", type=int, default=None, metavar="N",
                   help="learners per simulation: N goal-directed vehicles in each worker's scene, each a slot of the "
                        "batch (workers x N), respawned at a new start when its episode ends (in continuous "
                        "fidelity each decides when its behavior ends; --ppo overlap_update=true runs PPO's update "
                        "while the workers drive, here and with flat's controls). Recorded in the checkpoint: a "
                        "--resume keeps it. Default 1: the single ego")
    p.add_argument("--backend", choices=("process", "ray"), default="process",
                   help="where the environment workers run: local processes (default) or Ray actors")
    p.add_argument("--address", default=None,
                   help="with --backend ray: the cluster (ray://HEAD:10001 or auto); default: a local Ray instance")
    p.add_argument("--seed", type=int, default=0, help="seed of the run (episodes, weights, sampling)")
    p.add_argument("--out", default=None, help="run folder (default: runs/<kind>__<scenario>__<seed>__<time>)")
    p.add_argument("--init", default=None,
                   help="PPO actor initialisation: hbmp/hbmp-s 'il' (shipped, default), flat 'flat-il' (shipped; "
                        "default none), a .pt checkpoint, or 'none'")
    p.add_argument("--resume", default=None, help="continue from a run's checkpoint.pt (with the fidelity, M_t, R_t "
                                                  "and density it recorded, unless given)")
    p.add_argument("--observation", choices=("deformed", "vehicle_centric"), default=None,
                   help="M_t kind (default: the --init checkpoint's, else the env's: deformed)")
    p.add_argument("--road-profile", choices=("paper", "metric"), default=None,
                   help="R_t: the paper's ten entries or those and the stop distance and speed in metric units "
                        "(metric); default: the --init checkpoint's, else paper")
    p.add_argument("--fidelity", default=None,
                   help="env fidelity (default: il event, hbmp/hbmp-s continuous; flat: the control env's)")
    p.add_argument("--density", default=None, help="background traffic (empty, corl, regular, dense; default: the "
                                                    "scenario's)")
    p.add_argument("--reward", choices=ENV_REWARDS, default=None,
                   help="flat: the control env's reward: dense (the paper's baseline, r_T + sum r_t; default), sparse "
                        "(r_T) or carla (CARLA's RL baseline reward: route progress, speed gained, overlap events)")
    p.add_argument("--mask-actions", action="store_true", help="mask infeasible behaviors in the policy")
    p.add_argument("--critic-warmup", type=int, default=None, metavar="EPISODES",
                   help=f"PPO: episodes at the start in which only the critic learns (default: "
                        f"{CRITIC_WARMUP_EPISODES} from an IL actor, 0 from a random one)")
    p.add_argument("--ppo", action="append", default=[], metavar="NAME=VALUE",
                   help="PPO option, repeatable: any field of hbmp_bench.training.ppo.PPOConfig, e.g. "
                        "entropy_coef=0.001, anchor_coef=1, desired_kl=0.01, num_steps_per_env=256 "
                        "(defaults: the paper's values, rsl-rl's where it gives none)")
    p.add_argument("--save-every", type=int, default=SAVE_EVERY, help="checkpoint every N episodes")
    p.add_argument("--validate-every", type=int, default=0, metavar="N",
                   help="PPO and flat-il: every N episodes, evaluate the greedy policy on the hbmp-val suite "
                        "(held-out Town03 episodes) into validation.csv and keep the best as best.pt; 0: never")
    p.add_argument("--validate-episodes", type=int, default=None, metavar="N",
                   help="with --validate-every: the first N validation episodes per task, up to 50 (default: 20)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_train)

    p = subparsers.add_parser("curves", help="one PNG of r_T and r_T + Σr_t per episode for several training runs "
                                             "(and their greedy validations, where they have a validation.csv)")
    p.add_argument("runs", nargs="+", help="run folders (each with episodes.csv)")
    p.add_argument("--labels", nargs="*", default=None, help="one legend label per run (default: the folder names)")
    p.add_argument("--out", default="training_curves.png", help="PNG to write")
    p.add_argument("--window", type=int, default=50, help="moving-average window [episodes]")
    p.set_defaults(func=_cmd_curves)
