"""Imported by the evaluation pool's fork server, and only there (``pool.PRELOAD``): it makes the
fork server non-dumpable and the reaper of orphans.

The fork server forks every env and agent process; a process of the same user that could trace
it could make it fork tampered env processes. As the reaper of its descendants' orphans, it
inherits whatever an agent forked that outlived the agent, where the pool finds and kills it
(``sandbox.reap_orphans``). Import-time is the only hook the fork server offers (it imports its
preload modules and nothing else of ours), hence this module.
"""

import warnings

from hbmp_bench.evaluation.sandbox import adopt_orphans, protect_process

PROTECTED = protect_process()
"""Whether the fork server is now non-dumpable (False where ``prctl`` is not available)."""
ADOPTS_ORPHANS = adopt_orphans()
"""Whether the fork server now reaps its descendants' orphans."""

# the fork server reaps the orphans the pool kills, and would warn about each one
warnings.filterwarnings("ignore", message="forkserver: waitpid returned unexpected pid")
