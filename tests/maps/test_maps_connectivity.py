"""Each town's vehicle lane graph is strongly connected without U-turns."""

from __future__ import annotations

import pytest

from hbmp_bench.maps import TOWNS


def _vehicle_graph(net) -> dict[str, set[str]]:
    """Successors of each drivable non-internal edge via passenger connections,
    leaving out any connection that turns back onto the reverse edge."""
    edges = [e for e in net.getEdges(withInternal=False) if e.allows("passenger")]
    ids = {e.getID() for e in edges}
    graph = {}
    for e in edges:
        succ = set()
        for to, conns in e.getOutgoing().items():
            if to.getID() not in ids:
                continue
            if to.getToNode() is e.getFromNode() and to.getFromNode() is e.getToNode():
                continue  # a U-turn
            if any(c.getFromLane().allows("passenger") and c.getToLane().allows("passenger")
                   for c in conns):
                succ.add(to.getID())
        graph[e.getID()] = succ
    return graph


def _reach(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = {start}, [start]
    while todo:
        for nxt in graph[todo.pop()]:
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


@pytest.mark.parametrize("town", TOWNS)
def test_no_turnarounds(nets, town):
    for edge in nets[town].getEdges(withInternal=False):
        for to in edge.getOutgoing():
            assert not (to.getToNode() is edge.getFromNode()
                        and to.getFromNode() is edge.getToNode()), (edge.getID(), to.getID())


@pytest.mark.parametrize("town", TOWNS)
def test_strongly_connected(nets, town):
    graph = _vehicle_graph(nets[town])
    assert all(graph.values()), "dead end"
    reverse = {e: set() for e in graph}
    for a, succ in graph.items():
        for b in succ:
            reverse[b].add(a)
    start = sorted(graph)[0]
    assert _reach(graph, start) == set(graph)      # start reaches every edge
    assert _reach(reverse, start) == set(graph)    # every edge reaches start
