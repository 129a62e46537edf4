"""
Scenes: the planar scene's types, the constants of every kind, finding and parsing files.

Readers and writers: :mod:`mech_balance.schema.planar`, :mod:`mech_balance.schema.spatial`;
the schema: docs/scenes.md.  Values are SI; the papers' normalization is recorded, never applied.
"""

from dataclasses import dataclass, field, replace
import difflib
import functools
import os
from pathlib import Path

from mech_balance import conventions
from mech_balance.schema import fields, safe_yaml
from mech_balance.schema.fields import SceneError

SCHEMA_VERSION = 1

OUTPUTS = ('kinematics', 'shaking_wrench', 'driving_torque', 'bearing_reactions',
           'kinetic_energy')
"""What a scene can ask for; each implies the ones it depends on (see :func:`needs`)."""
DEFAULT_OUTPUTS = OUTPUTS[:4]
"""What a scene without an ``outputs:`` key asks for (``all``: every one of :data:`OUTPUTS`)."""
SERIES = {
    'driving_torque': ('driving torque', 'moment'),
    'driving_force': ('driving force', 'force'),
    'kinetic_energy': ('kinetic energy T', 'energy'),
}
"""The scalar series among the outputs: name -> (label, dimension 'force' | 'moment' |
'energy'); reports, JSON and plots show every series a rig computes from this table.  A
rig's driving effort is the series its :attr:`~mech_balance.core.rig.Rig.driving_series`
names (a prismatic input's: ``driving_force``)."""
SERIES_OUTPUTS = {'driving_force': 'driving_torque'}
"""The output a series of :data:`SERIES` answers where their names differ."""

JOINT_TYPES = ('revolute', 'prismatic')
FRAME = 'frame'
INERTIA_ROUNDOFF = 1e-12
"""Relative slack of the check inertia about the mass centre >= 0 (parallel-axis round-off);
buildability is :func:`mech_balance.core.equimomental.is_realizable`."""
COUNTERWEIGHT_MASS_REL_TOL = 1e-6
"""A counterweight's mass_kg must equal density * pi * R^2 * t to this relative tolerance."""
MAX_PLANE_OFFSET_M = 10.0
"""Largest |plane_m| of a counterweight (m): a disc's plane further from its link is a typo."""
RECORDING_STREAMS = (
    'frame', 'links', 'joints', 'mass_centres', 'point_masses', 'shaking_force_arrow',
    'shaking_moment_arc', 'shaking_force_plot', 'shaking_moment_plot', 'driving_torque_plot',
    'info',
)
"""What a rerun recording of the scene can show (``recording.streams``)."""
DEFAULT_OFF_STREAMS = ('point_masses',)
"""Streams a scene must switch on (``recording: {streams: {point_masses: true}}``); every
other stream is on unless switched off."""
DEFAULT_STREAMS = tuple(s for s in RECORDING_STREAMS if s not in DEFAULT_OFF_STREAMS)


def series_stream(name):
    """Return ``OUTPUT_plot``, the stream switching series ``name``'s plot."""
    return f'{SERIES_OUTPUTS.get(name, name)}_plot'


_CONFIG_DIRS = (Path(__file__).resolve().parents[2] / 'config',)


@dataclass(frozen=True)
class Normalization:
    """The papers' view: masses by m_1, lengths by a_1, time by 1/omega (seed 001 sec. 3.4)."""

    mass_kg: float
    length_m: float
    omega_rad_s: float

    def force(self, force_N):
        """Return a normalized force, f / (m_1 a_1 omega^2) (conventions.normalize_force)."""
        return conventions.normalize_force(force_N, self.mass_kg, self.length_m,
                                           self.omega_rad_s)

    def moment(self, moment_Nm):
        """Return a normalized moment or torque, n / (m_1 a_1^2 omega^2)."""
        return conventions.normalize_moment(moment_Nm, self.mass_kg, self.length_m,
                                            self.omega_rad_s)

    def energy(self, energy_J):
        """Return a normalized energy, E / (m_1 a_1^2 omega^2) (the unit of a moment)."""
        return conventions.normalize_moment(energy_J, self.mass_kg, self.length_m,
                                            self.omega_rad_s)

    @classmethod
    def parse(cls, data):
        """Return the validated ``normalization:`` of a scene mapping, or None without one."""
        if 'normalization' not in data:
            return None
        nd = fields.mapping(data['normalization'], 'normalization')
        fields.known_keys(nd, {'mass_kg', 'length_m', 'omega_rad_s'}, 'normalization')
        return cls(*(fields.positive(fields.require(nd, k, 'normalization'),
                                     f'normalization.{k}')
                     for k in ('mass_kg', 'length_m', 'omega_rad_s')))

    def keys(self):
        """Return the field names: a normalization reads as ``{mass_kg, length_m, ...}``."""
        return ('mass_kg', 'length_m', 'omega_rad_s')

    def items(self):
        """Return ``(name, value)`` pairs, as a mapping does."""
        return [(k, getattr(self, k)) for k in self.keys()]

    def __getitem__(self, key):
        """Return a field by name (``norm['mass_kg']``), as in the scene file."""
        if key not in self.keys():
            raise KeyError(key)
        return getattr(self, key)

    def __eq__(self, other):
        """Compare with another normalization or with its mapping form."""
        if isinstance(other, (Normalization, dict)):
            return all(self[k] == other[k] for k in self.keys()) and len(other.keys()) == 3
        return NotImplemented

    def __hash__(self):
        """Hash as the tuple of the three values."""
        return hash((self.mass_kg, self.length_m, self.omega_rad_s))


@dataclass(frozen=True)
class Counterweight:
    """
    A solid disc fixed to a link: a ``links.<name>.counterweights`` entry (SI).

    ``centre_m``: ``(x, y)`` in the link frame; ``plane_m``: mid-plane z from the link's plane;
    ``mount``: the point whose shaft carries it (docs/balancing.md#the-plane-of-a-counterweight).
    """

    mass_kg: float
    centre_m: tuple
    radius_m: float
    thickness_m: float
    density_kg_m3: float
    plane_m: float = 0.0
    mount: str = ''

    @property
    def inertia_com_kg_m2(self):
        """Return the disc's polar moment of inertia about its own centre, m R^2 / 2."""
        return 0.5 * self.mass_kg * self.radius_m ** 2

    def to_dict(self):
        """Return the disc as its scene entry (``mass_kg``, ``centre_m``, ...)."""
        out = {'mass_kg': float(self.mass_kg), 'centre_m': [float(v) for v in self.centre_m],
               'radius_m': float(self.radius_m), 'thickness_m': float(self.thickness_m),
               'density_kg_m3': float(self.density_kg_m3)}
        if self.plane_m != 0.0:   # the link's own plane is the default, not written
            out['plane_m'] = float(self.plane_m)
        if self.mount:
            out['mount'] = self.mount
        return out


def counterweight_totals(mass_kg, com_m, inertia_com_kg_m2, counterweights):
    """Return ``(mass_kg, com_m, inertia_com_kg_m2)`` of a link body plus its discs."""
    if not counterweights:
        return mass_kg, com_m, inertia_com_kg_m2
    m = mass_kg
    hx, hy = mass_kg * com_m[0], mass_kg * com_m[1]
    i_o = inertia_com_kg_m2 + mass_kg * (com_m[0] ** 2 + com_m[1] ** 2)
    for cw in counterweights:
        x, y = cw.centre_m
        m += cw.mass_kg
        hx += cw.mass_kg * x
        hy += cw.mass_kg * y
        i_o += cw.inertia_com_kg_m2 + cw.mass_kg * (x * x + y * y)
    com = (hx / m, hy / m)
    return m, com, max(i_o - m * (com[0] ** 2 + com[1] ** 2), 0.0)


@dataclass(frozen=True)
class Link:
    """
    A rigid link: named points and inertia in its own frame (SI).

    Mass properties are the TOTALS of body and ``counterweights``; the body alone is ``own_*``.
    """

    name: str
    points: dict
    mass_kg: float
    com_m: tuple
    inertia_com_kg_m2: float
    counterweights: tuple = ()
    own: tuple = None   # (mass_kg, com_m, inertia_com_kg_m2) of the body without the discs

    def __post_init__(self):
        """Drop discs that the totals do not contain (see the class docstring)."""
        if not self.counterweights and self.own is None:
            return
        if self.counterweights and self.own is not None and \
                counterweight_totals(*self.own, self.counterweights) == \
                (self.mass_kg, self.com_m, self.inertia_com_kg_m2):
            return
        object.__setattr__(self, 'counterweights', ())
        object.__setattr__(self, 'own', None)

    @property
    def own_mass_kg(self):
        """Return the mass of the link body without its counterweights."""
        return self.mass_kg if self.own is None else self.own[0]

    @property
    def own_com_m(self):
        """Return the mass centre of the link body without its counterweights."""
        return self.com_m if self.own is None else self.own[1]

    @property
    def own_inertia_com_kg_m2(self):
        """Return the centroidal inertia of the link body without its counterweights."""
        return self.inertia_com_kg_m2 if self.own is None else self.own[2]

    @property
    def first_moment_kg_m(self):
        """Return m*c, the first moment of mass about the link origin."""
        return (self.mass_kg * self.com_m[0], self.mass_kg * self.com_m[1])

    @property
    def inertia_origin_kg_m2(self):
        """Return the moment of inertia about the link origin (parallel axes)."""
        return self.inertia_com_kg_m2 + self.mass_kg * (self.com_m[0] ** 2 + self.com_m[1] ** 2)


def add_counterweights(link, counterweights):
    """Return ``link`` with more discs: same body, its totals include every disc."""
    own = (link.own_mass_kg, tuple(link.own_com_m), link.own_inertia_com_kg_m2)
    discs = tuple(link.counterweights) + tuple(counterweights)
    m, com, i_c = counterweight_totals(*own, discs)
    return replace(link, mass_kg=m, com_m=com, inertia_com_kg_m2=i_c, counterweights=discs,
                   own=own if discs else None)


@dataclass(frozen=True)
class Joint:
    """A joint between the points ``a`` and ``b`` (``link.point``) of two links."""

    name: str
    joint_type: str        # 'revolute' | 'prismatic' (JOINT_TYPES)
    link_a: str
    point_a: str
    link_b: str
    point_b: str
    axis: tuple = (1.0, 0.0)
    angle_rad: float = 0.0

    @property
    def prismatic(self):
        """Return whether the joint slides (else it turns)."""
        return self.joint_type == 'prismatic'

    @property
    def kind(self):
        """Return the joint type (the scene file's ``type``), as :attr:`joint_type`."""
        return self.joint_type


@dataclass(frozen=True)
class Recording:
    """What ``mech-balance record`` and the node's recording show (a scale None: from the data)."""

    streams: tuple = DEFAULT_STREAMS
    force_scale_m_per_N: float = None
    moment_scale_deg_per_Nm: float = None

    def enabled(self, stream):
        """Return whether ``stream`` (a name from :data:`RECORDING_STREAMS`) is switched on."""
        return stream in self.streams


class SceneDesigns:
    """The mixin of every kind's scene dataclass: its links by name and its other designs."""

    def link(self, name):
        """Return the link called ``name``."""
        for lk in self.links:
            if lk.name == name:
                return lk
        raise KeyError(name)

    def with_links(self, links, name=None):
        """Return a copy with other link inertias (same geometry), e.g. a balanced design."""
        return replace(self, links=tuple(links), name=name or self.name)

    def with_outputs(self, outputs):
        """Return a copy that asks for other outputs (validated)."""
        return replace(self, outputs=parse_outputs(list(outputs), 'outputs'))


@dataclass(frozen=True)
class Scene(SceneDesigns):
    """A validated planar rig (SI units throughout)."""

    name: str
    description: str
    frame_points: dict
    links: tuple
    joints: tuple
    crank_joint: str
    crank_speed_rad_s: float
    crank_acceleration_rad_s2: float
    assembly_crank_angle_rad: float
    assembly_link_angles_rad: dict
    assembly_displacements_m: dict
    outputs: tuple
    samples: int
    gravity_m_s2: tuple = (0.0, 0.0)
    normalization: Normalization = None
    notes: dict = field(default_factory=dict)
    source: str = '<dict>'
    kind: str = 'planar'
    recording: Recording = Recording()
    drive: dict = None  # motor, speed loop and damping for `mech-balance simulate`
    identification: dict = None  # what `mech-balance identify` found (schema.identification)
    build: dict = None  # the rig as built, layer by layer (schema.build; None: drawn sizes)


def needs(outputs):
    """Return the frozenset of computations ``outputs`` need (kinematics < ... < reactions)."""
    return _needs_of(frozenset(outputs))   # the core asks once per evaluation: remembered


@functools.lru_cache(maxsize=64)
def _needs_of(outputs):
    out = set(outputs)
    if 'bearing_reactions' in out:
        out |= {'driving_torque'}
    if 'driving_torque' in out or 'shaking_wrench' in out:
        out |= {'accelerations'}
    out |= {'kinematics'}
    return frozenset(out)


def builtin_scenes():
    """Return ``{name: path}`` of the scenes shipped in ``config/``."""
    found = {}
    for d in _config_dirs():
        for p in sorted(d.glob('*.yaml')):
            if p.name.endswith('_params.yaml'):
                continue
            found.setdefault(p.stem, p)
    return found


def _config_dirs():
    dirs = list(_CONFIG_DIRS)
    try:  # installed by colcon: share/mech_balance/config
        from ament_index_python.packages import get_package_share_directory
        dirs.append(Path(get_package_share_directory('mech_balance')) / 'config')
    except Exception:  # noqa: BLE001 - ament index absent or package not installed
        pass
    return [d for d in dirs if d.is_dir()]


SCENE_NAME_CUTOFF = 0.6
"""difflib similarity above which a misspelled scene name is answered with the nearest one."""


def resolve(name_or_path):
    """Return the path of a built-in scene name or of a YAML file."""
    text = str(name_or_path)
    if os.sep in text or text.endswith(('.yaml', '.yml')):
        # missing, a directory, /dev/null, empty or too large: said as such (safe_yaml)
        return safe_yaml.check_file(text, 'scene', error=SceneError)
    scenes = builtin_scenes()
    if text not in scenes:
        near = difflib.get_close_matches(text, scenes, n=1, cutoff=SCENE_NAME_CUTOFF)
        raise SceneError(
            f'scene: got {text!r}, expected a built-in scene ({", ".join(sorted(scenes))}) '
            'or a path to a .yaml file' + (f'; did you mean {near[0]!r}?' if near else ''))
    return scenes[text]


def parse_yaml(text, label='YAML'):
    """Parse YAML text as scenes are parsed (:mod:`mech_balance.schema.safe_yaml`: bounded)."""
    return safe_yaml.loads(text, label, error=SceneError)


def load_data(name_or_path):
    """Return the parsed YAML mapping of a scene and its path."""
    path = resolve(name_or_path)
    data = safe_yaml.load_file(path, f'scene {path.name}', error=SceneError)
    if not isinstance(data, dict):
        raise SceneError(f'scene {path.name}: got {type(data).__name__}, expected a mapping')
    data.setdefault('name', path.stem)
    return data, path


def parse_outputs(value, where):
    """Return a validated ``outputs:`` list as a tuple in :data:`OUTPUTS` order."""
    if value == 'all':
        return OUTPUTS
    if not isinstance(value, (list, tuple)) or not value:
        raise SceneError(f'{where}: got {value!r}, expected a list from {", ".join(OUTPUTS)}')
    for v in value:
        if v not in OUTPUTS:
            raise SceneError(f'{where}: got {v!r}, expected one of {", ".join(OUTPUTS)}')
    return tuple(o for o in OUTPUTS if o in value)
