"""Training machinery: an rsl-rl ``VecEnv`` over worker processes, the paper's network with a
categorical behavior distribution, PPO with the paper's hyper-parameters, and DAgger from the
rule-based expert.

Submodules are imported where used (``hbmp_bench.training.vec_env`` and friends) so that the
environment workers, which import :mod:`hbmp_bench.training.worker`, never load torch.
"""
