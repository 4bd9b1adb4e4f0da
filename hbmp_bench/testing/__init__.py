"""Checks for agent authors: a short smoke run of an agent, and its pytest plugin.

    def test_my_agent(hbmp_smoke):                 # the fixture comes with the package
        hbmp_smoke("my_package.agents:MyAgent")    # fails with a readable message

Or without pytest: ``hbmp_bench.testing.smoke_run("my_package.agents:MyAgent")``.

The names load on first access: pytest loads the plugin, and so this package, in every session.
"""

from hbmp_bench._lazy import lazy_exports

__all__ = ["SmokeConfig", "SmokeFailure", "SmokeResult", "smoke_run"]

__getattr__, __dir__ = lazy_exports(__name__, {".smoke": ("SmokeConfig", "SmokeFailure", "SmokeResult", "smoke_run")})
