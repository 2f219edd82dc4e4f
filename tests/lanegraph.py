"""Lane-graph helpers shared by the suite and spawner tests."""

from __future__ import annotations

from collections import deque


def reaches_by_following(road_map, start: int, target: int) -> bool:
    """Whether lane `target` is reached from lane `start` by lane following alone (through
    non-junction lanes; `target` itself may be a junction lane)."""
    lanes, seen, queue = road_map.lanes, {start}, deque([start])
    while queue:
        x = queue.popleft()
        for q in lanes.successors(x):
            if int(q) == target:
                return True
            if q not in seen and not lanes.in_junction[q]:
                seen.add(int(q))
                queue.append(int(q))
    return False
