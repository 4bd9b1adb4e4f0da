"""A module a hostile checkpoint names as its network class (``checkpoint_payload:Evil``): importing
it leaves ``pwned-checkpoint`` (with the uid it ran as) in ``HBMP_TEST_AGENT_DIR``. The package must
never import it while building a policy."""

import os
from pathlib import Path

folder = os.environ.get("HBMP_TEST_AGENT_DIR")
if folder:
    Path(folder, "pwned-checkpoint").write_text(str(os.getuid()))

from hbmp_bench.policies.networks import BehaviorNetwork  # noqa: E402


class Evil(BehaviorNetwork):
    """The package's network, under another name."""
