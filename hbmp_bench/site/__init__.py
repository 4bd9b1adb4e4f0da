"""The project's two sites: the static leaderboard website (``hbmp-bench site --out DIR``, built from the
committed boards) and the docs site's generated API reference (:mod:`hbmp_bench.site.apidocs`, a mkdocs
hook)."""
