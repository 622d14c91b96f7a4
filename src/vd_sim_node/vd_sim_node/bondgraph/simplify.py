"""Optional graph rewrite: merge rigidly coupled inertias (a simple derivative causality).

Two inertias whose flows are tied by the junction structure alone (the same 1-junction,
1-junctions joined by plain bonds, or by constant TFs) are dependent: SCAP puts one of them
in derivative causality. Like 20-sim's suggestion, the fix is to merge them into one I with
the inertia reflected onto one junction: m = sum(m_i * k_i**2), where k_i is the flow ratio
of the junction of I_i to the group's first junction. Only linear I elements are merged.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from .elements import Element, Kind
from .errors import ElementDefinitionError
from .graph import BondGraph

__all__ = ['MergeResult', 'merge_rigid_inertias']


@dataclass(frozen=True)
class MergeResult:
    """The rewritten graph and what was merged.

    Attributes:
        graph: a new graph (the input graph is not modified).
        merged: new I name -> names of the linear I elements it replaces.
        inertia: new I name -> its inertia (reflected onto the group's first junction).
    """

    graph: BondGraph
    merged: dict[str, tuple[str, ...]]
    inertia: dict[str, float]


def _flow_groups(graph: BondGraph) -> list[dict[str, float]]:
    """Groups of 1-junctions with rigidly tied flows: junction -> flow ratio to the root."""
    seen: set[str] = set()
    groups: list[dict[str, float]] = []
    for root in graph.elements.values():
        if root.kind is not Kind.ONE or root.name in seen:
            continue
        ratios = {root.name: 1.0}
        queue = deque([root.name])
        seen.add(root.name)
        while queue:
            name = queue.popleft()
            for bond_name in graph.elements[name].bonds:
                bond = graph.bonds[bond_name]
                neighbour = graph.elements[bond.other(name)]
                ratio = ratios[name]
                if neighbour.kind is Kind.TF and neighbour.law is None:
                    assert neighbour.param is not None
                    # Through a constant TF: f1 = n * f0 (port 0 points into the TF).
                    if len(neighbour.bonds) != 2:
                        continue
                    far_bond = next(b for b in neighbour.bonds if b != bond_name)
                    far = graph.elements[graph.bonds[far_bond].other(neighbour.name)]
                    into_tf = graph.bonds[bond_name].into(neighbour.name) > 0
                    ratio = ratio * neighbour.param if into_tf else ratio / neighbour.param
                    neighbour = far
                if neighbour.kind is Kind.ONE and neighbour.name not in seen:
                    seen.add(neighbour.name)
                    ratios[neighbour.name] = ratio
                    queue.append(neighbour.name)
        groups.append(ratios)
    return groups


def merge_rigid_inertias(graph: BondGraph) -> MergeResult:
    """Merge every group of two or more linear I elements with rigidly tied flows.

    The merged I is named by joining the merged names with '+', sits on the group's first
    1-junction with its bond pointing in, and takes the place (in element order, hence state
    order) of the first merged I. Everything else is copied unchanged.

    Raises:
        ElementDefinitionError: a sensor reads a bond that disappears in the merge.
    """
    replaced: dict[str, str] = {}  # old I -> new I name
    merged: dict[str, tuple[str, ...]] = {}
    inertia: dict[str, float] = {}
    home: dict[str, str] = {}  # new I -> junction it attaches to
    for ratios in _flow_groups(graph):
        members: list[tuple[str, float]] = []
        for junction, ratio in ratios.items():
            for bond_name in graph.elements[junction].bonds:
                other = graph.elements[graph.bonds[bond_name].other(junction)]
                if other.kind is Kind.I and other.param is not None:
                    members.append((other.name, other.param * ratio * ratio))
        if len(members) < 2:
            continue
        new_name = '+'.join(name for name, _ in members)
        merged[new_name] = tuple(name for name, _ in members)
        inertia[new_name] = sum(m for _, m in members)
        home[new_name] = next(iter(ratios))
        for name, _ in members:
            replaced[name] = new_name
    if not merged:
        return MergeResult(graph, {}, {})
    removed_bonds = {graph.elements[name].bonds[0] for name in replaced}
    for sensor in graph.sensors.values():
        if sensor.bond in removed_bonds:
            raise ElementDefinitionError(
                f'sensor {sensor.name!r} reads bond {sensor.bond!r}, which the inertia merge '
                f'removes; attach it to another bond of the same junction'
            )
    out = BondGraph(graph.name)
    for inp in graph.inputs.values():
        out.add_input(inp.name, inp.default)
    for element in graph.elements.values():
        if element.name in replaced:
            new_name = replaced[element.name]
            if new_name not in out.elements:
                out.add_i(new_name, inertia[new_name])
            continue
        out._add(
            Element(
                element.name,
                element.kind,
                element.param,
                element.law,
                element.conductance_law,
                element.energy,
                element.signals,
            )
        )
    for bond in graph.bonds.values():
        if bond.name not in removed_bonds:
            out.connect(bond.tail, bond.head, bond.name)
    for new_name, junction in home.items():
        out.connect(junction, new_name)
    for sensor in graph.sensors.values():
        (out.add_effort_sensor if sensor.quantity == 'e' else out.add_flow_sensor)(
            sensor.name, sensor.bond
        )
    for block in graph.blocks.values():
        out.add_block(block.name, block.fn, signals=block.signals)
    return MergeResult(out, merged, inertia)
