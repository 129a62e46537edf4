"""
The registry of scene kinds: the one place that knows which kinds of rig exist.

Each :class:`Kind` names its loader, writer, scene type and role implementations by import
path, so the schema never imports the core (docs/design.md#the-rig-protocol).
"""

from dataclasses import dataclass
import importlib

from mech_balance.schema import planar, rggr_legacy, scene, spatial
from mech_balance.schema.fields import SceneError


@dataclass(frozen=True)
class Kind:
    """A registered kind of scene and rig."""

    name: str
    scene_type: type
    load: object             # (mapping, source) -> scene
    write: object            # scene -> mapping (the inverse of load)
    implementations: dict    # role -> 'module:attribute': rig, analyze, urdf, urdf_tree
    geometry: object = None  # scene -> (what a design may not change, its name in words)

    def implementation(self, role):
        """Return this kind's implementation of ``role`` (imported on first use)."""
        module, _, attr = self.implementations[role].partition(':')
        return getattr(importlib.import_module(module), attr)

    def rig_factory(self):
        """Return the rig factory (scene -> Rig)."""
        return self.implementation('rig')


KINDS = {
    'planar': Kind('planar', scene.Scene, planar.planar_from_dict, planar.planar_to_dict, {
        'rig': 'mech_balance.core.planar.rig:PlanarRig',
        'analyze': 'mech_balance.analysis.cycle:analyze',
        'urdf': 'mech_balance.ros.urdf:planar_robot',
        'urdf_tree': 'mech_balance.ros.urdf:planar_tree'}, planar.geometry),
    'spatial': Kind('spatial', spatial.SpatialScene, spatial.spatial_from_dict,
                    spatial.spatial_to_dict, {
                        'rig': 'mech_balance.core.spatial.rig:SpatialRig',
                        'analyze': 'mech_balance.analysis.spatial_report:analyze',
                        'urdf': 'mech_balance.ros.urdf:spatial_robot',
                        'urdf_tree': 'mech_balance.ros.urdf:spatial_tree'}, spatial.geometry),
}
"""Every kind of scene, by its ``kind:`` value; ``planar`` is the default."""
DEFAULT_KIND = 'planar'


def kind_named(name):
    """Return the :class:`Kind` of a ``kind:`` value, or a SceneError listing the kinds."""
    try:
        return KINDS[name]
    except (KeyError, TypeError):
        raise SceneError(f'kind: got {name!r}, expected '
                         + ' or '.join(f'"{k}"' for k in KINDS)) from None


def kind_of(obj):
    """Return the :class:`Kind` of a scene, or of a rig (through its ``scene``)."""
    sc = getattr(obj, 'scene', obj)
    for kind in KINDS.values():
        if isinstance(sc, kind.scene_type):
            return kind
    raise TypeError(f'got {type(obj).__name__}, expected a scene of a registered kind '
                    f'({", ".join(KINDS)}) or a rig built from one')


def from_dict(data, source='<dict>'):
    """Validate a parsed scene mapping with the loader of its ``kind`` (default planar)."""
    if not isinstance(data, dict):
        raise SceneError(f'scene: got {type(data).__name__}, expected a mapping')
    if data.get('kind') == rggr_legacy.KIND:   # the former closed-form RGGR: its spatial scene
        data = rggr_legacy.translate(data, source)
    return kind_named(data.get('kind', DEFAULT_KIND)).load(data, source=source)


def to_dict(sc):
    """Return a scene as the mapping its kind's loader reads back."""
    return kind_of(sc).write(sc)


def same_geometry(base, design, field='design'):
    """Raise SceneError unless ``design`` is ``base`` with other inertias (same kind, geometry)."""
    kind = kind_of(base)
    other = kind_of(design)
    if other is not kind:
        raise SceneError(f'{field}: got a {other.name} scene ({design.name!r}), expected a '
                         f'{kind.name} scene like the original {base.name!r}')
    mine, what = kind.geometry(base)
    if kind.geometry(design)[0] != mine:
        raise SceneError(f'{field}: scene {design.name!r} ({design.source}) differs from '
                         f'{base.name!r} in its {what}; expected the same geometry with '
                         'other inertias')
