"""The task tree kept by hierarchical agents (ReCAP, ADaPT): nodes with every (think, subtasks)
version they had, turned into ``tree_nodes`` records at the end of an episode."""

from __future__ import annotations

from dataclasses import dataclass, field

from schemas.kinds import NodeKind, NodeStatus
from schemas.records import NodeRecord, NodeVersion


@dataclass
class Node:
    """One subtask: its place in the tree, its kind and status, and its plan versions."""

    node_id: int
    parent: Node | None
    depth: int
    child_index: int
    task: str
    kind: NodeKind = "composite"
    status: NodeStatus = "open"
    versions: list[NodeVersion] = field(default_factory=list)
    step_index: int | None = None
    n_children: int = 0

    @property
    def subtasks(self) -> tuple[str, ...]:
        return self.versions[-1].subtasks if self.versions else ()

    @property
    def thinks(self) -> list[str]:
        return [v.think for v in self.versions if v.think]

    def add_version(self, think: str | None, subtasks: tuple[str, ...], call_index: int | None, seq: int | None) -> None:
        self.versions.append(NodeVersion(len(self.versions), think, tuple(subtasks), call_index, seq))

    def record(self, episode_id: str) -> NodeRecord:
        return NodeRecord(
            episode_id=episode_id,
            node_id=self.node_id,
            parent_id=self.parent.node_id if self.parent else None,
            depth=self.depth,
            child_index=self.child_index,
            task=self.task,
            kind=self.kind,
            status=self.status,
            versions=tuple(self.versions),
            step_index=self.step_index,
        )
