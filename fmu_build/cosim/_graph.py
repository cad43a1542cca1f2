"""The connection graph of a system: algebraic loops, exchange and stepping orders; interpolation weights."""

import math

import numpy as np


def _graph(components, connections):
    """Variable-level feedthrough graph, its cycles, and an exchange order.

    Nodes are ``(component, variable)``; edges: source output -> destination
    input (a connection), input -> output of the same FMU (direct feedthrough).
    Returns the strongly connected components with more than one node (the
    algebraic loops) and a topological order of the nodes after cutting the
    connection edges that close a cycle.
    """
    edges = {}
    for a, y, b, u in connections:
        edges.setdefault((a, y), []).append((b, u))
        edges.setdefault((b, u), [])
    for a, y, b, u in connections:
        for out, deps in components[b].feedthrough.items():
            if u in deps:
                edges[(b, u)].append((b, out))
                edges.setdefault((b, out), [])
    sccs = _strongly_connected(edges)
    loops = [sorted(s) for s in sccs if len(s) > 1]
    # cut connection edges until no cycle is left (the destination input then lags one exchange): a loop may
    # hold several cycles, each needs a cut; on each cycle found the connection listed first is cut
    rank = {((a, y), (b, u)): i for i, (a, y, b, u) in reversed(list(enumerate(connections)))}
    cut = set()
    while True:
        cycle = _cycle(edges, cut)
        if cycle is None:
            break
        # every cycle holds a connection (an output's only successors are the inputs it feeds)
        cut.add(min((e for e in zip(cycle, cycle[1:] + cycle[:1]) if e in rank), key=rank.get))
    # Kahn's topological sort on the rest
    indeg = {v: 0 for v in edges}
    for v, ws in edges.items():
        for w in ws:
            if (v, w) not in cut:
                indeg[w] += 1
    ready = [v for v in edges if indeg[v] == 0]
    order = []
    while ready:
        v = ready.pop(0)
        order.append(v)
        for w in edges[v]:
            if (v, w) in cut:
                continue
            indeg[w] -= 1
            if indeg[w] == 0:
                ready.append(w)
    return loops, order, cut


def _cycle(edges, removed):
    """A cycle (its nodes in order) of the graph ``edges`` without the edges ``removed``, or None (iterative
    depth-first search)."""
    state, parent = {}, {}  # state: 1 on the current path, 2 done
    for root in edges:
        if root in state:
            continue
        state[root] = 1
        work = [(root, iter(edges[root]))]
        while work:
            node, it = work[-1]
            for w in it:
                if (node, w) in removed:
                    continue
                if state.get(w) == 1:  # a back edge: the path from w to node closes a cycle
                    path = [node]
                    while path[-1] != w:
                        path.append(parent[path[-1]])
                    return path[::-1]
                if w not in state:
                    state[w], parent[w] = 1, node
                    work.append((w, iter(edges[w])))
                    break
            else:
                state[node] = 2
                work.pop()
    return None


def _strongly_connected(edges):
    """Tarjan's strongly connected components of the graph ``edges`` (node -> successors), iteratively."""
    index, low, stack, on, sccs, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        work = [(v, iter(edges[v]))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        while work:
            node, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(edges[w])))
                    break
                if w in on:
                    low[node] = min(low[node], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    scc = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        scc.append(w)
                        if w == node:
                            break
                    sccs.append(scc)

    for v in list(edges):
        if v not in index:
            visit(v)
    return sccs


def _component_order(names, connections, feedthrough=()):
    """Gauss-Seidel order: sources before destinations; inside a cycle, the FMUs whose connected
    outputs have no direct feedthrough first (their new values are consistent before the others
    step), then the listed order."""
    succ = {n: set() for n in names}
    for a, _, b, _ in connections:
        if a != b:
            succ[a].add(b)
    # strongly connected components by reachability (systems are small)
    reach = {}
    for n in names:
        seen, todo = set(), [n]
        while todo:
            for m in succ[todo.pop()]:
                if m not in seen:
                    seen.add(m)
                    todo.append(m)
        reach[n] = seen
    groups = []
    for n in names:
        if any(n in g for g in groups):
            continue
        group = [m for m in names if m == n or (m in reach[n] and n in reach[m])]
        groups.append(sorted(group, key=lambda m: m in feedthrough))
    # order groups: a group goes after every group that reaches it and is not reached by it
    ordered = []
    remaining = list(groups)
    while remaining:
        for g in remaining:
            blockers = [h for h in remaining if h is not g and any(x in reach[y] for y in h for x in g)
                        and not any(x in reach[y] for y in g for x in h)]
            if not blockers:
                ordered.append(g)
                remaining.remove(g)
                break
    return [n for g in ordered for n in g]


def _weights(nodes, at, order):
    """Weights w with sum_j w_j v(nodes_j) = d^order/dt^order of the interpolating polynomial at ``at``."""
    nodes = np.asarray(nodes, dtype=float)
    m = len(nodes)
    if order >= m:
        return np.zeros(m)
    # Vandermonde in (t - at): coefficient c_k of (t - at)^k; derivative = k! c_k
    V = np.vander(nodes - at, m, increasing=True)
    return math.factorial(order) * np.linalg.solve(V.T, np.eye(m)[order])
