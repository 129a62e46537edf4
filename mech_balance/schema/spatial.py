"""
The spatial scene (``kind: spatial``): any single-input spatial linkage; loader and writer.

Values are stored as given (the core normalizes), so :func:`spatial_to_dict` round-trips
exactly; the schema: docs/scenes.md#spatial-schema-kind-spatial.
"""

from dataclasses import dataclass, field
import math

from mech_balance import conventions
from mech_balance.schema import fields
from mech_balance.schema.drive import drive_from_dict
from mech_balance.schema.fields import SceneError
from mech_balance.schema.scene import DEFAULT_OUTPUTS, FRAME, Normalization, \
    parse_outputs, SceneDesigns

KIND = 'spatial'
"""Value of the top-level ``kind`` field of a spatial scene."""
SCHEMA_VERSION = 1
JOINT_TYPES = ('revolute', 'prismatic', 'cylindrical', 'universal', 'spherical')
"""Joint types of a spatial scene."""
JOINT_FREEDOMS = {'revolute': 1, 'prismatic': 1, 'cylindrical': 2, 'universal': 2,
                  'spherical': 3}
"""Relative freedoms of each joint type."""
AXIS_JOINTS = ('revolute', 'prismatic', 'cylindrical', 'universal')
"""Joint types that have an axis."""
INPUT_TYPES = ('revolute', 'prismatic')
"""Joint types that can be the input (crank) joint."""
INERTIA_RTOL = 1e-12
"""Relative slack (of the trace) of the PSD and triangle-inequality checks of an inertia."""
AXIS_MIN = 1e-9
"""Smallest norm of a joint axis (relative to its largest component's scale 1)."""
MIN_SAMPLES = 4
"""Fewest crank angles per revolution of ``samples``."""
CRANK_KEYS = {'joint', 'speed_rad_s', 'acceleration_rad_s2', 'stroke_m'}
"""The fields of ``crank:`` (``stroke_m``: a prismatic input only)."""
POSE_TOL_DEG = 5.0
"""How far (deg) a link's solved rotation, and a joint's two axes, may be from the stated
assembly poses."""
POSE_TOL_REL = 0.05
"""How far a link's stated origin may be from its solved one, relative to the linkage's size
(the largest distance between two of its points)."""


def stroke_law(stroke_m, psi):
    """Return ``(s, ds/dpsi, d2s/dpsi2)`` (m) of a prismatic input's Scotch yoke at ``psi``."""
    s_min, s_max = stroke_m
    centre, half = 0.5 * (s_min + s_max), 0.5 * (s_max - s_min)
    if isinstance(psi, (int, float)):
        cos, sin = math.cos(psi), math.sin(psi)
    else:
        import numpy as np  # on first use: the command line parsers need none
        cos, sin = np.cos(psi), np.sin(psi)
    return centre - half * cos, half * sin, half * cos


@dataclass(frozen=True)
class SpatialLink:
    """A rigid link: named points, mass, mass centre and inertia, in its own axes (SI)."""

    name: str
    points: dict
    mass_kg: float
    com_m: tuple
    inertia_com_kg_m2: tuple      # (ixx, iyy, izz, ixy, ixz, iyz)

    def inertia_matrix(self):
        """Return the 3x3 inertia tensor about the mass centre (nested tuples)."""
        ixx, iyy, izz, ixy, ixz, iyz = self.inertia_com_kg_m2
        return ((ixx, ixy, ixz), (ixy, iyy, iyz), (ixz, iyz, izz))


@dataclass(frozen=True)
class SpatialJoint:
    """A joint between the points ``a`` and ``b`` (``link.point``) of two links."""

    name: str
    joint_type: str
    link_a: str
    point_a: str
    link_b: str
    point_b: str
    axis: tuple = None        # in link a's axes, as given
    axis_b: tuple = None      # in link b's axes, as given (None: the numbers of ``axis``)
    angle_deg: float = None   # prismatic: b's fixed turn about the axis

    @property
    def freedoms(self):
        """Return the number of relative freedoms of the joint."""
        return JOINT_FREEDOMS[self.joint_type]

    @property
    def prismatic(self):
        """Return True for a prismatic joint (it slides, it does not turn)."""
        return self.joint_type == 'prismatic'


@dataclass(frozen=True)
class Pose:
    """An approximate link pose for the assembly: origin (m) and roll-pitch-yaw (deg)."""

    origin_m: tuple = (0.0, 0.0, 0.0)
    rpy_deg: tuple = (0.0, 0.0, 0.0)

    def rotation(self):
        """Return the rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` (3, 3) of ``rpy_deg`` (URDF)."""
        from mech_balance.rotations import rpy_matrix  # on first use: the parsers need no numpy
        return rpy_matrix(self.rpy_deg, degrees=True)


@dataclass(frozen=True)
class WeightSpec:
    """A seed 002 balancing weight on a frame-pivoted link: ``mass_kg`` or eq. 13's cylinder."""

    link: str
    joint: str
    mass_kg: float = None
    density_length_kg_m2: float = None


@dataclass(frozen=True)
class SpatialScene(SceneDesigns):
    """A validated spatial scene (values as given, SI)."""

    name: str
    description: str
    frame_points: dict
    links: tuple
    joints: tuple
    crank_joint: str
    crank_speed_rad_s: float
    crank_acceleration_rad_s2: float
    moment_point_m: tuple
    assembly_crank_angle_deg: float
    assembly_poses: dict
    crank_stroke_m: tuple = None   # (s_min, s_max), m: a prismatic input only
    outputs: tuple = DEFAULT_OUTPUTS
    samples: int = conventions.DEFAULT_SAMPLES
    normalization: Normalization = None
    notes: dict = field(default_factory=dict)
    source: str = '<dict>'
    kind: str = KIND
    balancing_weights: tuple = ()   # WeightSpec per link (seed 002's method ``weights``)
    drive: dict = None  # motor, speed loop, damping, flywheel for `mech-balance simulate`

    @property
    def assembly_crank_angle_rad(self):
        """Return the assembly crank coordinate in rad, reduced exactly into one turn (fmod)."""
        return math.radians(math.fmod(self.assembly_crank_angle_deg, 360.0))


_TOP_KEYS = {'kind', 'schema_version', 'name', 'description', 'normalization', 'frame',
             'links', 'joints', 'crank', 'moment_point_m', 'assembly', 'outputs', 'samples',
             'notes', 'balance', 'balancing_weights', 'drive'}
WEIGHT_KEYS = ('mass_kg', 'density_length_kg_m2')
"""The fields of one ``balancing_weights`` entry (exactly one of them)."""


def _vec3(value, where):
    return fields.vector(value, where, 3)


def check_inertia(tensor, where):
    """
    Raise SceneError naming ``where`` for an inertia (ixx, iyy, izz, ixy, ixz, iyz) no body has.

    Positive semi-definite and the triangle inequality, to :data:`INERTIA_RTOL` of the trace.
    """
    import numpy as np  # on first use: the command line parsers need none
    ixx, iyy, izz, ixy, ixz, iyz = tensor
    m = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    eig = np.linalg.eigvalsh(m)
    slack = INERTIA_RTOL * max(abs(ixx) + abs(iyy) + abs(izz), 1e-300)
    if eig[0] < -slack:
        raise SceneError(
            f'{where}: got {list(tensor)}, whose principal moments {[float(e) for e in eig]} '
            'include a negative one; expected a positive semi-definite inertia tensor')
    if eig[2] > eig[0] + eig[1] + slack:
        raise SceneError(
            f'{where}: got {list(tensor)}, whose principal moments {[float(e) for e in eig]} '
            f'break the triangle inequality ({eig[2]:.6g} > {eig[0]:.6g} + {eig[1]:.6g}); '
            'expected each principal moment <= the sum of the other two (a rigid body)')
    return tensor


def _link(name, spec):
    where = f'links.{name}'
    spec = fields.mapping(spec, where)
    fields.known_keys(spec, {'points', 'mass_kg', 'com_m', 'inertia_com_kg_m2',
                             'description'}, where)
    points = fields.points(fields.require(spec, 'points', where), f'{where}.points', size=3)
    mass = fields.nonneg(fields.require(spec, 'mass_kg', where), f'{where}.mass_kg')
    com = _vec3(spec.get('com_m', [0.0, 0.0, 0.0]), f'{where}.com_m')
    raw = fields.require(spec, 'inertia_com_kg_m2', where)
    ipath = f'{where}.inertia_com_kg_m2'
    if not isinstance(raw, (list, tuple)) or len(raw) != 6:
        raise SceneError(f'{ipath}: got {raw!r}, expected six numbers [ixx, iyy, izz, ixy, '
                         'ixz, iyz] (kg m^2, about the mass centre in the link axes)')
    tensor = tuple(fields.number(v, f'{ipath}[{i}]') for i, v in enumerate(raw))
    check_inertia(tensor, ipath)
    if mass == 0.0 and any(tensor):
        raise SceneError(f'{ipath}: got {list(tensor)} for a massless link ({where}.mass_kg '
                         '= 0), expected all zeros')
    return SpatialLink(name, points, mass, com, tensor)


def _axis(value, where):
    axis = _vec3(value, where)
    if math.sqrt(sum(x * x for x in axis)) < AXIS_MIN:
        raise SceneError(f'{where}: got {list(axis)}, expected a non-zero direction')
    return axis


def _joint(name, spec, all_points):
    where = f'joints.{name}'
    spec = fields.mapping(spec, where)
    fields.known_keys(spec, {'type', 'a', 'b', 'axis', 'axis_b', 'angle_deg',
                             'description'}, where)
    jtype = fields.require(spec, 'type', where)
    if jtype not in JOINT_TYPES:
        raise SceneError(f'{where}.type: got {jtype!r}, expected one of '
                         f'{", ".join(JOINT_TYPES)}')
    ends = fields.joint_ends(spec, where, all_points)
    axis = axis_b = angle = None
    if jtype in AXIS_JOINTS:
        axis = _axis(fields.require(spec, 'axis', where), f'{where}.axis')
        if jtype == 'universal':
            axis_b = _axis(fields.require(spec, 'axis_b', where), f'{where}.axis_b')
        elif 'axis_b' in spec:
            axis_b = _axis(spec['axis_b'], f'{where}.axis_b')
    elif 'axis' in spec or 'axis_b' in spec:
        raise SceneError(f'{where}: a spherical joint has no axis, expected no axis or axis_b')
    if 'angle_deg' in spec:
        if jtype != 'prismatic':
            raise SceneError(f'{where}.angle_deg: applies to prismatic joints only (got type '
                             f'{jtype})')
        angle = fields.number(spec['angle_deg'], f'{where}.angle_deg')
    return SpatialJoint(name, jtype, ends[0][0], ends[0][1], ends[1][0], ends[1][1], axis,
                        axis_b, angle)


def _stroke(crank, cj):
    """Return ``crank.stroke_m`` as ``(s_min, s_max)`` for a prismatic input, else None."""
    where = 'crank.stroke_m'
    if not cj.prismatic:
        if 'stroke_m' in crank:
            raise SceneError(f'{where}: got {crank["stroke_m"]!r} for the {cj.joint_type} '
                             f'input joint {cj.name!r}; expected no stroke_m (a stroke '
                             'applies to a prismatic input only)')
        return None
    if 'stroke_m' not in crank:
        raise SceneError(f'{where}: missing for the prismatic input joint {cj.name!r}; '
                         'expected [s_min, s_max], the slide range (m) the Scotch-yoke '
                         'drive covers over one cycle')
    raw = crank['stroke_m']
    if not isinstance(raw, (list, tuple)) or len(raw) != 2:
        raise SceneError(f'{where}: got {raw!r}, expected [s_min, s_max] (m)')
    s_min, s_max = (fields.number(v, f'{where}[{i}]') for i, v in enumerate(raw))
    if not s_min < s_max:
        raise SceneError(f'{where}: got {list(raw)!r}, expected [s_min, s_max] with '
                         's_min < s_max (m)')
    return (s_min, s_max)


def _pose(spec, where):
    spec = fields.mapping(spec, where)
    fields.known_keys(spec, {'origin_m', 'rpy_deg'}, where)
    return Pose(_vec3(spec.get('origin_m', [0.0, 0.0, 0.0]), f'{where}.origin_m'),
                _vec3(spec.get('rpy_deg', [0.0, 0.0, 0.0]), f'{where}.rpy_deg'))


def _check_axes_at_poses(joints, poses):
    """
    Refuse a joint whose axes disagree at the stated poses (:data:`POSE_TOL_DEG`), naming it.

    The message gives the ``axis_b`` the poses imply; joints of an unposed link are skipped.
    """
    import numpy as np  # on first use: the command line parsers need none
    eye = np.eye(3)
    for jt in joints:
        if jt.axis is None or (jt.link_a != FRAME and jt.link_a not in poses) or \
                (jt.link_b != FRAME and jt.link_b not in poses):
            continue
        rot_a = eye if jt.link_a == FRAME else poses[jt.link_a].rotation()
        rot_b = eye if jt.link_b == FRAME else poses[jt.link_b].rotation()
        a = np.array(jt.axis, dtype=float)
        b = np.array(jt.axis if jt.axis_b is None else jt.axis_b, dtype=float)
        wa, wb = rot_a @ (a / np.linalg.norm(a)), rot_b @ (b / np.linalg.norm(b))
        where = f'joints.{jt.name}.axis_b'
        if jt.joint_type == 'universal':
            off = math.degrees(math.asin(min(1.0, abs(float(wa @ wb)))))
            if off > POSE_TOL_DEG:
                raise SceneError(
                    f'{where}: got {list(jt.axis_b)}, which is {90.0 - off:.4g} deg (not 90) '
                    "from the joint's axis at the stated poses (assembly.poses of "
                    f'{jt.link_a} and {jt.link_b}); expected the cross axis fixed in link '
                    f'{jt.link_b}, normal to axis at those poses (to {POSE_TOL_DEG:g} deg), or '
                    'poses that make them normal')
            continue
        off = math.degrees(math.atan2(float(np.linalg.norm(np.cross(wa, wb))), float(wa @ wb)))
        if off <= POSE_TOL_DEG:
            continue
        implied = [float(f'{v:.6g}') for v in rot_b.T @ wa]
        got = (f'missing, and its default (the numbers of axis, {list(jt.axis)}) is'
               if jt.axis_b is None else f'got {list(jt.axis_b)}, which is')
        raise SceneError(
            f"{where}: {got} {off:.4g} deg from the joint's axis at the stated poses "
            f'(assembly.poses of {jt.link_a} and {jt.link_b}); expected the same line in '
            f"link {jt.link_b}'s axes, {implied} at those poses (to {POSE_TOL_DEG:g} deg), "
            'or poses that align the two')


def spatial_from_dict(data, source='<dict>'):
    """Validate a parsed spatial scene mapping into a SpatialScene (raises SceneError)."""
    data = fields.mapping(data, 'scene')
    fields.known_keys(data, _TOP_KEYS, '')
    if data.get('kind') != KIND:
        raise SceneError(f'kind: got {data.get("kind")!r}, expected {KIND!r}')
    version = data.get('schema_version', SCHEMA_VERSION)
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        raise SceneError(f'schema_version: got {version!r}, expected {SCHEMA_VERSION}')
    name = fields.string(data.get('name', 'spatial'), 'name')
    description = fields.text(data.get('description', ''), 'description')
    frame = fields.mapping(fields.require(data, 'frame', ''), 'frame')
    fields.known_keys(frame, {'points'}, 'frame')
    frame_points = fields.points(fields.require(frame, 'points', 'frame'), 'frame.points',
                                 size=3)

    links_data = fields.mapping(fields.require(data, 'links', ''), 'links')
    if not links_data:
        raise SceneError('links: got an empty mapping, expected at least one moving link')
    fields.at_most(links_data, conventions.MAX_LINKS, 'links', 'moving links', 'MAX_LINKS')
    if FRAME in links_data:
        raise SceneError(f'links.{FRAME}: "{FRAME}" is reserved for the fixed link')
    links = tuple(_link(n, spec) for n, spec in links_data.items())

    joints_data = fields.mapping(fields.require(data, 'joints', ''), 'joints')
    if not joints_data:
        raise SceneError('joints: got an empty mapping, expected the joints of the linkage')
    fields.at_most(joints_data, conventions.MAX_JOINTS, 'joints', 'joints', 'MAX_JOINTS')
    all_points = {FRAME: frame_points, **{lk.name: lk.points for lk in links}}
    joints = tuple(_joint(n, spec, all_points) for n, spec in joints_data.items())
    fields.check_connected(links, joints, FRAME)

    crank = fields.mapping(fields.require(data, 'crank', ''), 'crank')
    fields.known_keys(crank, CRANK_KEYS, 'crank')
    crank_joint, cj = fields.crank_joint(crank, joints)
    if cj.joint_type not in INPUT_TYPES or FRAME not in (cj.link_a, cj.link_b):
        raise SceneError(
            f'crank.joint: got {crank_joint!r} ({cj.joint_type} between {cj.link_a} and '
            f'{cj.link_b}), expected a revolute or prismatic joint between the frame and a '
            'moving link')
    stroke = _stroke(crank, cj)
    speed = fields.nonzero(crank.get('speed_rad_s', 1.0), 'crank.speed_rad_s')
    accel = fields.number(crank.get('acceleration_rad_s2', 0.0), 'crank.acceleration_rad_s2')
    moment_point = _vec3(fields.require(data, 'moment_point_m', ''), 'moment_point_m')

    assembly = fields.mapping(data.get('assembly', {}) or {}, 'assembly')
    fields.known_keys(assembly, {'crank_angle_deg', 'poses'}, 'assembly')
    crank_angle = fields.number(assembly.get('crank_angle_deg', 0.0),
                                'assembly.crank_angle_deg')
    poses = {}
    names = {lk.name for lk in links}
    for k, v in fields.mapping(assembly.get('poses', {}) or {}, 'assembly.poses').items():
        if k not in names:
            raise SceneError(f'assembly.poses.{k}: no such link, expected one of '
                             f'{", ".join(sorted(names))}')
        poses[k] = _pose(v, f'assembly.poses.{k}')
    _check_axes_at_poses(joints, poses)

    normalization = Normalization.parse(data)
    outputs = parse_outputs(data.get('outputs', list(DEFAULT_OUTPUTS)), 'outputs')
    samples = fields.integer(data.get('samples', conventions.DEFAULT_SAMPLES), 'samples',
                             MIN_SAMPLES)
    try:
        conventions.check_samples(samples, 'samples', links=len(links))
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    weights = _weights(data.get('balancing_weights', {}) or {}, joints)
    notes = data.get('notes', {})
    if 'balance' in data:
        fields.mapping(data['balance'], 'balance')
    return SpatialScene(
        name=name, description=description.strip(), frame_points=frame_points, links=links,
        joints=joints, crank_joint=crank_joint, crank_speed_rad_s=speed,
        crank_acceleration_rad_s2=accel, moment_point_m=moment_point,
        assembly_crank_angle_deg=crank_angle, assembly_poses=poses, crank_stroke_m=stroke,
        outputs=outputs,
        samples=samples, normalization=normalization,
        notes=notes if isinstance(notes, dict) else {'text': notes}, source=str(source),
        balancing_weights=weights, drive=_drive(data.get('drive')))


def _weights(data, joints):
    """Return the :class:`WeightSpec` tuple of ``balancing_weights``."""
    data = fields.mapping(data, 'balancing_weights')
    out = []
    for link, spec in data.items():
        where = f'balancing_weights.{link}'
        pivots = [j for j in joints if j.joint_type == 'revolute'
                  and {j.link_a, j.link_b} == {FRAME, link}]
        if len(pivots) != 1:
            raise SceneError(f'{where}: link {link!r} has {len(pivots)} revolute joints with '
                             "the frame, expected one (a weight in Hedaya's method turns about a "
                             'fixed axis)')
        spec = fields.mapping(spec, where)
        fields.known_keys(spec, set(WEIGHT_KEYS), where)
        given = [k for k in WEIGHT_KEYS if k in spec]
        if len(given) != 1:
            raise SceneError(f'{where}: got {", ".join(given) or "neither"}, expected exactly '
                             f'one of {" or ".join(WEIGHT_KEYS)}')
        value = fields.positive(spec[given[0]], f'{where}.{given[0]}')
        out.append(WeightSpec(link, pivots[0].name, **{given[0]: value}))
    return tuple(out)


def _drive(data):
    """Return the ``drive`` mapping as given, its fields checked (joint names: on simulation)."""
    if data is not None:
        drive_from_dict(data)
    return data


def _joint_dict(jt):
    spec = {'type': jt.joint_type, 'a': f'{jt.link_a}.{jt.point_a}',
            'b': f'{jt.link_b}.{jt.point_b}'}
    if jt.axis is not None:
        spec['axis'] = list(jt.axis)
    if jt.axis_b is not None:
        spec['axis_b'] = list(jt.axis_b)
    if jt.angle_deg is not None:
        spec['angle_deg'] = jt.angle_deg
    return spec


def spatial_to_dict(scene):
    """Return a :class:`SpatialScene` as the mapping :func:`spatial_from_dict` reads back."""
    data = {'kind': KIND, 'schema_version': SCHEMA_VERSION, 'name': scene.name,
            'description': scene.description}
    if scene.normalization is not None:
        data['normalization'] = dict(scene.normalization.items())
    data['frame'] = {'points': {k: list(v) for k, v in scene.frame_points.items()}}
    data['links'] = {lk.name: {'points': {k: list(v) for k, v in lk.points.items()},
                               'mass_kg': lk.mass_kg, 'com_m': list(lk.com_m),
                               'inertia_com_kg_m2': list(lk.inertia_com_kg_m2)}
                     for lk in scene.links}
    data['joints'] = {jt.name: _joint_dict(jt) for jt in scene.joints}
    data['crank'] = {'joint': scene.crank_joint, 'speed_rad_s': scene.crank_speed_rad_s,
                     'acceleration_rad_s2': scene.crank_acceleration_rad_s2}
    if scene.crank_stroke_m is not None:
        data['crank']['stroke_m'] = list(scene.crank_stroke_m)
    data['moment_point_m'] = list(scene.moment_point_m)
    assembly = {'crank_angle_deg': scene.assembly_crank_angle_deg}
    if scene.assembly_poses:
        assembly['poses'] = {k: {'origin_m': list(p.origin_m), 'rpy_deg': list(p.rpy_deg)}
                             for k, p in scene.assembly_poses.items()}
    data['assembly'] = assembly
    data['outputs'] = list(scene.outputs)
    data['samples'] = int(scene.samples)
    if scene.balancing_weights:
        data['balancing_weights'] = {
            w.link: ({'mass_kg': w.mass_kg} if w.mass_kg is not None else
                     {'density_length_kg_m2': w.density_length_kg_m2})
            for w in scene.balancing_weights}
    if scene.notes:
        data['notes'] = scene.notes
    if scene.drive is not None:
        data['drive'] = scene.drive
    return data


def geometry(scene):
    """Return what a design of a spatial scene may not change, and its name in words."""
    return ((scene.frame_points, [(lk.name, lk.points) for lk in scene.links], scene.joints,
             scene.crank_joint, scene.crank_stroke_m, scene.assembly_crank_angle_deg,
             scene.assembly_poses),
            'frame points, link points, joints, input stroke and assembly')
