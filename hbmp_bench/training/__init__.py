"""Training machinery: one :class:`~hbmp_bench.training.session.TrainingSession` (resume, seeding, workers,
logs, checkpoints, model card) driven by the DAgger (:mod:`~hbmp_bench.training.dagger`) and PPO
(:mod:`~hbmp_bench.training.ppo`, the paper's hyper-parameters) loops, over an rsl-rl ``VecEnv`` of worker
processes. The networks and checkpoint files are :mod:`hbmp_bench.policies`' (the floor below this room).

Submodules are imported where used (``hbmp_bench.training.vec_env`` and friends) so that the
environment workers, which import :mod:`hbmp_bench.training.worker`, never load torch.
"""
