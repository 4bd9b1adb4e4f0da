"""Policies: the paper's M_t/R_t network (:mod:`~hbmp_bench.policies.networks`), its categorical behavior
distribution (:mod:`~hbmp_bench.policies.distributions`) and checkpoint files
(:mod:`~hbmp_bench.policies.checkpoints`: writing, weights-only reading, building the policy a file holds).

The floor below both :mod:`hbmp_bench.agents` (inference: a learned agent builds its network from a
checkpoint) and :mod:`hbmp_bench.training` (which writes them): it imports neither, so an agent process
never loads training code. Submodules are imported where used; ``checkpoints`` imports torch only in the
functions that need it.
"""
