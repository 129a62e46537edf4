"""Reading a recording back with rerun's loader (``rerun.chunk.RrdReader``)."""

from dataclasses import dataclass

import numpy as np


@dataclass
class EntityData:
    """
    One entity of a recording read back, its rows in time order.

    ``static``, ``columns`` (a value per row), ``index`` (timeline -> values; ``time`` in s).
    """

    static: dict
    columns: dict
    index: dict

    @property
    def rows(self):
        """Return the number of logged (non-static) rows."""
        return len(next(iter(self.index.values()))) if self.index else 0


def read_recording(path):
    """Return ``{entity_path: EntityData}`` of an ``.rrd`` file, by rerun's own loader."""
    from rerun.chunk import RrdReader
    entities = {}
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        data = entities.setdefault(chunk.entity_path, EntityData({}, {}, {}))
        names = [n for n in batch.schema.names if not n.startswith('rerun.controls')]
        if chunk.is_static:
            for n in names:
                data.static[n] = batch.column(n).to_pylist()[-1]
            continue
        timelines = set(chunk.timeline_names)
        for n in names:
            col = batch.column(n)
            if n in timelines:
                values = col.to_numpy()
                if np.issubdtype(values.dtype, np.timedelta64):
                    values = values.astype('timedelta64[ns]').astype(np.int64) * 1e-9
                data.index.setdefault(n, []).append(np.asarray(values))
            else:
                data.columns.setdefault(n, []).extend(col.to_pylist())
    for data in entities.values():
        data.index = {k: np.concatenate(v) for k, v in data.index.items()}
        key = data.index.get('time', data.index.get('crank_angle'))
        if key is not None and np.any(np.diff(key) < 0):
            order = np.argsort(key, kind='stable')
            data.index = {k: v[order] for k, v in data.index.items()}
            data.columns = {k: [v[i] for i in order] for k, v in data.columns.items()}
    return entities


def read_blueprint(path):
    """
    Return the views of an ``.rrd`` file's blueprint: ``[{kind, name, origin, ...}]``.

    With ``bounds`` (2-D) and ``eye`` (3-D) where set.
    """
    from rerun.chunk import RrdReader
    reader = RrdReader(str(path))
    views, props = {}, {}
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            cols = {n: batch.column(n).to_pylist() for n in batch.schema.names
                    if n not in ('log_time', 'log_tick', 'blueprint')}
            entity = chunk.entity_path
            if 'ViewBlueprint:class_identifier' in cols:
                for kind, name, origin in zip(cols['ViewBlueprint:class_identifier'],
                                              cols['ViewBlueprint:display_name'],
                                              cols['ViewBlueprint:space_origin']):
                    views[entity] = {'kind': kind[0], 'name': name[0] if name else '',
                                     'origin': origin[0] if origin else ''}
            view = '/'.join(entity.split('/')[:3])
            if 'VisualBounds2D:range' in cols:
                props.setdefault(view, {})['bounds'] = cols['VisualBounds2D:range'][-1][0]
            if 'EyeControls3D:position' in cols:
                props.setdefault(view, {})['eye'] = {
                    k: tuple(cols[f'EyeControls3D:{k}'][-1][0])
                    for k in ('position', 'look_target', 'eye_up')
                    if f'EyeControls3D:{k}' in cols}
    for entity, view in views.items():
        view.update(props.get(entity, {}))
    return sorted(views.values(), key=lambda v: (v['kind'], v['name'], v['origin']))


def read_blueprint_views(path):
    """Return ``[(kind, name, origin)]`` of the views in an ``.rrd`` file's blueprint."""
    return sorted((v['kind'], v['name'], v['origin']) for v in read_blueprint(path))
