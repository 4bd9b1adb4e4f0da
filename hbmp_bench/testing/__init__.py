"""Checks for agent authors: a short smoke run of an agent, and its pytest plugin.

    def test_my_agent(hbmp_smoke):                 # the fixture comes with the package
        hbmp_smoke("my_package.agents:MyAgent")    # fails with a readable message

Or without pytest: ``hbmp_bench.testing.smoke_run("my_package.agents:MyAgent")``.
"""

from hbmp_bench.testing.smoke import SmokeConfig, SmokeFailure, SmokeResult, smoke_run

__all__ = ["SmokeConfig", "SmokeFailure", "SmokeResult", "smoke_run"]
