"""Reading a ``.rrd`` recording back (``rerun.chunk.RrdReader``): what the tests check."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from cnt_env.replay.rerun import import_rerun

__all__ = ["read_rrd"]


def read_rrd(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What a ``.rrd`` file holds (with ``rerun.chunk.RrdReader``).

    Returns ``recordings`` (the recording ids), ``application_ids``, ``blueprints``
    (count), ``rows`` (entity path -> number of temporal rows), ``static`` (entity
    paths with static data), ``timelines`` (every timeline name), ``scalars`` (entity
    path -> list of (step, value), for ``Scalars`` entities logged on ``step``) and
    ``texts`` (the TextLog lines). Entity paths start with ``/``.
    """
    import_rerun()
    from rerun.chunk import RrdReader

    reader = RrdReader(Path(path))
    recordings = reader.recordings()
    rows: dict[str, int] = {}
    static: set[str] = set()
    timelines: set[str] = set()
    scalars: dict[str, list[tuple[int, float]]] = {}
    texts: list[str] = []
    for chunk in reader.stream():
        entity = chunk.entity_path
        if chunk.is_static:
            static.add(entity)
            continue
        rows[entity] = rows.get(entity, 0) + chunk.num_rows
        timelines.update(chunk.timeline_names)
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "Scalars:scalars" in names and "step" in names:
            steps = batch.column("step").to_pylist()
            values = batch.column("Scalars:scalars").to_pylist()
            scalars.setdefault(entity, []).extend(
                (int(s), float(v[0])) for s, v in zip(steps, values, strict=True) if v
            )
        if "TextLog:text" in names:
            texts.extend(
                t[0] if isinstance(t, list) else t
                for t in batch.column("TextLog:text").to_pylist()
                if t
            )
    for series in scalars.values():
        series.sort()
    return {
        "recordings": [r.recording_id for r in recordings],
        "application_ids": [r.application_id for r in recordings],
        "blueprints": len(reader.blueprints()),
        "rows": rows,
        "static": sorted(static),
        "timelines": sorted(timelines),
        "scalars": scalars,
        "texts": texts,
    }
