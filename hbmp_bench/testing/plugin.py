"""pytest plugin of hbmp_bench (registered through the ``pytest11`` entry point): the ``hbmp_smoke`` fixture.

Agent authors check an agent before submitting it with a three-line test::

    def test_my_agent_smoke(hbmp_smoke):
        hbmp_smoke("my_package.agents:MyAgent")

``hbmp_smoke(agent, **options)`` runs :func:`hbmp_bench.testing.smoke_run` (options are
:class:`hbmp_bench.testing.SmokeConfig` fields, e.g. ``max_decision_s=0.2``) and fails the test
with a readable list of what went wrong, or returns the :class:`SmokeResult`.
"""

from __future__ import annotations

import pytest


@pytest.fixture
def hbmp_smoke():
    """Callable ``(agent, **SmokeConfig options) -> SmokeResult`` that fails the test on a bad agent."""
    from hbmp_bench.testing.smoke import SmokeConfig, SmokeFailure, smoke_run

    def run(agent: str, **options):
        config = SmokeConfig(**options)
        try:
            return smoke_run(agent, config)
        except SmokeFailure as exc:
            pytest.fail(str(exc), pytrace=False)

    return run
