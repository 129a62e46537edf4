"""The planar kind's scene reader and writer: YAML mapping <-> :class:`Scene` (docs/scenes.md)."""

from dataclasses import replace
import math

from mech_balance import conventions
from mech_balance.schema import fields
from mech_balance.schema.build import build_from_dict
from mech_balance.schema.drive import drive_from_dict
from mech_balance.schema.fields import at_most as _at_most, check_connected, joint_ends, \
    known_keys as _known_keys, mapping as _mapping, number as _number, points as _points, \
    positive as _positive, require as _require, SceneError, string as _string, vector as _vector
from mech_balance.schema.scene import add_counterweights, Counterweight, \
    COUNTERWEIGHT_MASS_REL_TOL, DEFAULT_OFF_STREAMS, DEFAULT_OUTPUTS, FRAME, \
    INERTIA_ROUNDOFF, Joint, JOINT_TYPES, Link, MAX_PLANE_OFFSET_M, Normalization, \
    parse_outputs, Recording, RECORDING_STREAMS, Scene, SCHEMA_VERSION

_TOP_KEYS = {
    'schema_version', 'name', 'description', 'kind', 'normalization', 'crank', 'gravity_m_s2',
    'frame', 'links', 'joints', 'assembly', 'outputs', 'samples', 'notes', 'recording',
    'balance', 'drive', 'identification', 'build',
}


def planar_from_dict(data, source='<dict>'):
    """Validate a parsed planar scene mapping (docs/scenes.md)."""
    _known_keys(data, _TOP_KEYS, '')
    version = data.get('schema_version', SCHEMA_VERSION)
    if version != SCHEMA_VERSION:
        raise SceneError(f'schema_version: got {version!r}, expected {SCHEMA_VERSION}')
    name = _string(data.get('name', 'scene'), 'name')
    frame = _mapping(_require(data, 'frame', ''), 'frame')
    _known_keys(frame, {'points'}, 'frame')
    frame_points = _points(_require(frame, 'points', 'frame'), 'frame.points')

    links_data = _mapping(_require(data, 'links', ''), 'links')
    if not links_data:
        raise SceneError('links: got an empty mapping, expected at least one moving link')
    _at_most(links_data, conventions.MAX_LINKS, 'links', 'moving links', 'MAX_LINKS')
    links = tuple(_link(n, spec) for n, spec in links_data.items())
    names = {lk.name for lk in links}
    if FRAME in names:
        raise SceneError(f'links.{FRAME}: "{FRAME}" is reserved for the fixed link')

    joints_data = _mapping(_require(data, 'joints', ''), 'joints')
    _at_most(joints_data, conventions.MAX_JOINTS, 'joints', 'joints', 'MAX_JOINTS')
    all_points = {FRAME: frame_points, **{lk.name: lk.points for lk in links}}
    joints = tuple(_joint(n, spec, all_points) for n, spec in joints_data.items())

    crank = _mapping(_require(data, 'crank', ''), 'crank')
    _known_keys(crank, {'joint', 'speed_rad_s', 'acceleration_rad_s2'}, 'crank')
    crank_joint, cj = fields.crank_joint(crank, joints)
    by_name = {j.name: j for j in joints}
    if cj.prismatic or FRAME not in (cj.link_a, cj.link_b) or cj.link_a == cj.link_b:
        raise SceneError(
            f'crank.joint: got {crank_joint!r} ({cj.joint_type} between {cj.link_a} and '
            f'{cj.link_b}), expected a revolute joint between the frame and a moving link')
    speed = _number(crank.get('speed_rad_s', 1.0), 'crank.speed_rad_s')
    if speed == 0.0:
        raise SceneError('crank.speed_rad_s: got 0.0, expected a non-zero crank speed (rad/s)')
    accel = _number(crank.get('acceleration_rad_s2', 0.0), 'crank.acceleration_rad_s2')

    _check_mobility(links, joints)

    assembly = _mapping(_require(data, 'assembly', ''), 'assembly')
    _known_keys(assembly, {'crank_angle_deg', 'link_angles_deg', 'joint_displacements_m'},
                'assembly')
    crank_angle = math.radians(
        _number(assembly.get('crank_angle_deg', 0.0), 'assembly.crank_angle_deg'))
    link_angles = {}
    for k, v in _mapping(assembly.get('link_angles_deg', {}),
                         'assembly.link_angles_deg').items():
        if k not in names:
            raise SceneError(
                f'assembly.link_angles_deg.{k}: no such link, expected one of '
                f'{", ".join(sorted(names))}')
        link_angles[k] = math.radians(_number(v, f'assembly.link_angles_deg.{k}'))
    displacements = {}
    for k, v in _mapping(assembly.get('joint_displacements_m', {}),
                         'assembly.joint_displacements_m').items():
        if k not in by_name or not by_name[k].prismatic:
            raise SceneError(
                f'assembly.joint_displacements_m.{k}: expected the name of a prismatic joint')
        displacements[k] = _number(v, f'assembly.joint_displacements_m.{k}')

    normalization = Normalization.parse(data)
    gravity = _vector(data.get('gravity_m_s2', [0.0, 0.0]), 'gravity_m_s2')
    outputs = parse_outputs(data.get('outputs', list(DEFAULT_OUTPUTS)), 'outputs')
    samples = data.get('samples', 360)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 4:
        raise SceneError(f'samples: got {samples!r}, expected an integer >= 4')
    try:  # at most MAX_SAMPLES, and bounded work for this many links
        conventions.check_samples(samples, 'samples', links=len(links))
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    notes = data.get('notes', {})
    if 'balance' in data:  # provenance written by `mech-balance balance --output`
        _mapping(data['balance'], 'balance')
    description = fields.text(data.get('description', ''), 'description')
    sc = Scene(
        name=name, description=description.strip(), frame_points=frame_points,
        links=links, joints=joints, crank_joint=crank_joint, crank_speed_rad_s=speed,
        crank_acceleration_rad_s2=accel, assembly_crank_angle_rad=crank_angle,
        assembly_link_angles_rad=link_angles, assembly_displacements_m=displacements,
        outputs=outputs, samples=samples, gravity_m_s2=gravity, normalization=normalization,
        notes=notes if isinstance(notes, dict) else {'text': notes}, source=source,
        recording=_recording(data.get('recording', {})), drive=data.get('drive'),
        build=build_from_dict(data.get('build'), [FRAME] + [lk.name for lk in links]))
    if sc.drive is not None:  # checked now, used by `mech-balance simulate`
        drive_from_dict(sc.drive, sc)
    if 'identification' in data:  # written by `mech-balance identify --output`
        from mech_balance.schema.identification import identification_from_dict
        sc = replace(sc, identification=identification_from_dict(
            data['identification'], [lk.name for lk in links]))
    return sc


def planar_to_dict(scene):
    """
    Return a planar scene as the mapping :func:`planar_from_dict` reads back.

    Raises SceneError for a link with a negative centroidal inertia (no body has one).
    """
    for lk in scene.links:
        if lk.inertia_com_kg_m2 < 0.0:
            raise SceneError(
                f'links.{lk.name}.inertia_com_kg_m2: got {lk.inertia_com_kg_m2:.6g}, expected '
                '>= 0; an unrealizable design cannot be saved as a scene')
    data = {'schema_version': SCHEMA_VERSION, 'name': scene.name,
            'description': scene.description, 'kind': 'planar'}
    if scene.normalization is not None:
        data['normalization'] = dict(scene.normalization.items())
    data['crank'] = {'joint': scene.crank_joint, 'speed_rad_s': scene.crank_speed_rad_s,
                     'acceleration_rad_s2': scene.crank_acceleration_rad_s2}
    data['gravity_m_s2'] = list(scene.gravity_m_s2)
    data['frame'] = {'points': {k: list(v) for k, v in scene.frame_points.items()}}
    # a link with counterweights: its own body and its discs (the loader adds them up)
    data['links'] = {lk.name: {'points': {k: list(v) for k, v in lk.points.items()},
                               'mass_kg': lk.own_mass_kg, 'com_m': list(lk.own_com_m),
                               'inertia_com_kg_m2': lk.own_inertia_com_kg_m2,
                               **({'counterweights': [cw.to_dict() for cw in
                                                      lk.counterweights]}
                                  if lk.counterweights else {})}
                     for lk in scene.links}
    joints = {}
    for jt in scene.joints:
        spec = {'type': jt.joint_type, 'a': f'{jt.link_a}.{jt.point_a}',
                'b': f'{jt.link_b}.{jt.point_b}'}
        if jt.prismatic:
            spec['axis'] = list(jt.axis)
            spec['angle_deg'] = math.degrees(jt.angle_rad)
        joints[jt.name] = spec
    data['joints'] = joints
    assembly = {'crank_angle_deg': math.degrees(scene.assembly_crank_angle_rad)}
    if scene.assembly_link_angles_rad:
        assembly['link_angles_deg'] = {k: math.degrees(v) for k, v in
                                       scene.assembly_link_angles_rad.items()}
    if scene.assembly_displacements_m:
        assembly['joint_displacements_m'] = dict(scene.assembly_displacements_m)
    data['assembly'] = assembly
    data['outputs'] = list(scene.outputs)
    data['samples'] = int(scene.samples)
    if scene.notes:
        data['notes'] = scene.notes
    if scene.recording != Recording():
        data['recording'] = recording_to_dict(scene.recording)
    if scene.drive is not None:
        data['drive'] = scene.drive
    if scene.build is not None:
        data['build'] = scene.build
    if scene.identification is not None:
        from mech_balance.schema.identification import identification_to_dict
        data['identification'] = identification_to_dict(scene.identification)
    return data


def geometry(scene):
    """Return what a design of a planar scene may not change, and its name in words."""
    return ((scene.frame_points, [(lk.name, lk.points) for lk in scene.links], scene.joints,
             scene.crank_joint), 'frame points, link points and joints')


def recording_to_dict(recording):
    """Return a :class:`Recording` as its ``recording:`` mapping (a ``None`` scale left out)."""
    out = {'streams': {s: recording.enabled(s) for s in RECORDING_STREAMS}}
    for key in ('force_scale_m_per_N', 'moment_scale_deg_per_Nm'):
        if getattr(recording, key) is not None:
            out[key] = getattr(recording, key)
    return out


def _recording(value):
    """Validate ``recording: {streams: {name: bool}, force_scale_m_per_N, ...}``."""
    if value is None:
        return Recording()
    value = _mapping(value, 'recording')
    _known_keys(value, {'streams', 'force_scale_m_per_N', 'moment_scale_deg_per_Nm'},
                'recording')
    switches = _mapping(value.get('streams', {}) or {}, 'recording.streams')
    _known_keys(switches, set(RECORDING_STREAMS), 'recording.streams')
    for k, v in switches.items():
        if not isinstance(v, bool):
            raise SceneError(f'recording.streams.{k}: got {v!r}, expected true or false')
    scales = {k: None if value.get(k) is None else _positive(value[k], f'recording.{k}')
              for k in ('force_scale_m_per_N', 'moment_scale_deg_per_Nm')}
    return Recording(tuple(s for s in RECORDING_STREAMS
                           if switches.get(s, s not in DEFAULT_OFF_STREAMS)), **scales)


def _check_mobility(links, joints):
    # Gruebler-Kutzbach for planar linkages: M = 3 n - 2 j (revolute and prismatic joints).
    n, j = len(links), len(joints)
    mobility = 3 * n - 2 * j
    if mobility != 1:
        raise SceneError(
            f'joints: {n} moving links and {j} joints give mobility 3*{n} - 2*{j} = '
            f'{mobility}, expected a single-degree-of-freedom linkage (mobility 1)')
    check_connected(links, joints, FRAME)


def _link(name, spec):
    where = f'links.{name}'
    spec = _mapping(spec, where)
    _known_keys(spec, {'points', 'mass_kg', 'com_m', 'inertia_com_kg_m2',
                       'inertia_origin_kg_m2', 'description', 'counterweights'}, where)
    points = _points(_require(spec, 'points', where), f'{where}.points')
    names = list(points)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if points[a] == points[b]:
                raise SceneError(
                    f'{where}.points: {a} and {b} are both at {list(points[a])}, a link of '
                    'length 0; expected distinct joint points')
    mass = _positive(_require(spec, 'mass_kg', where), f'{where}.mass_kg')
    com = _vector(spec.get('com_m', [0.0, 0.0]), f'{where}.com_m')
    has_c, has_o = 'inertia_com_kg_m2' in spec, 'inertia_origin_kg_m2' in spec
    if has_c == has_o:
        raise SceneError(
            f'{where}: give exactly one of inertia_com_kg_m2 and inertia_origin_kg_m2 '
            f'(got {"both" if has_c else "neither"})')
    d2 = com[0] ** 2 + com[1] ** 2
    if has_c:
        i_c = _number(spec['inertia_com_kg_m2'], f'{where}.inertia_com_kg_m2')
        key, value = 'inertia_com_kg_m2', i_c
    else:
        i_o = _number(spec['inertia_origin_kg_m2'], f'{where}.inertia_origin_kg_m2')
        i_c = i_o - mass * d2
        key, value = 'inertia_origin_kg_m2', i_o
    # A rigid body's centroidal polar moment of inertia is >= 0 (zero: a point mass); the
    # slack only absorbs the round-off of the parallel-axis subtraction.
    scale = max(abs(value), mass * d2, 1e-300)
    if i_c < -INERTIA_ROUNDOFF * scale:
        raise SceneError(
            f'{where}.{key}: got {value!r}, which gives a centroidal moment of inertia '
            f'{i_c:.6g} kg*m^2 < 0; no body has that (expected inertia about the mass centre '
            '>= 0)')
    link = Link(name, points, mass, com, max(i_c, 0.0))
    discs = spec.get('counterweights') or []
    if not isinstance(discs, list):
        raise SceneError(f'{where}.counterweights: got {discs!r}, expected a list of discs '
                         '{mass_kg, centre_m, radius_m, thickness_m, density_kg_m3}')
    discs = [_counterweight(d, f'{where}.counterweights[{k}]') for k, d in enumerate(discs)]
    for k, d in enumerate(discs):
        if d.mount and d.mount not in points:
            raise SceneError(f'{where}.counterweights[{k}].mount: got {d.mount!r}, expected a '
                             f'point of the link ({", ".join(points)})')
    return add_counterweights(link, discs) if discs else link


def _counterweight(spec, where):
    spec = _mapping(spec, where)
    keys = ('mass_kg', 'centre_m', 'radius_m', 'thickness_m', 'density_kg_m3')
    _known_keys(spec, set(keys) | {'plane_m', 'mount'}, where)
    for key in keys:
        _require(spec, key, where)
    mass = _positive(spec['mass_kg'], f'{where}.mass_kg')
    centre = _vector(spec['centre_m'], f'{where}.centre_m')
    radius = _positive(spec['radius_m'], f'{where}.radius_m')
    thickness = _positive(spec['thickness_m'], f'{where}.thickness_m')
    density = _positive(spec['density_kg_m3'], f'{where}.density_kg_m3')
    solid = density * math.pi * radius ** 2 * thickness
    if abs(solid - mass) > COUNTERWEIGHT_MASS_REL_TOL * mass:
        raise SceneError(
            f'{where}.mass_kg: got {mass!r}, but density_kg_m3 * pi * radius_m^2 * '
            f'thickness_m = {solid:.9g} kg; expected them equal (relative '
            f'{COUNTERWEIGHT_MASS_REL_TOL:g}): mass_kg or one of the dimensions is inconsistent')
    plane = _number(spec.get('plane_m', 0.0), f'{where}.plane_m') + 0.0   # -0.0 is 0.0
    if abs(plane) > MAX_PLANE_OFFSET_M:
        raise SceneError(f'{where}.plane_m: got {plane!r}, expected a z offset from the '
                         f"link's plane within +-{MAX_PLANE_OFFSET_M:g} m")
    mount = spec.get('mount', '')
    if mount != '':
        _string(mount, f'{where}.mount')
    return Counterweight(mass, centre, radius, thickness, density, plane, mount)


def _joint(name, spec, all_points):
    where = f'joints.{name}'
    spec = _mapping(spec, where)
    _known_keys(spec, {'type', 'a', 'b', 'axis', 'angle_deg', 'description'}, where)
    jtype = _require(spec, 'type', where)
    if jtype not in JOINT_TYPES:
        raise SceneError(f'{where}.type: got {jtype!r}, expected one of {", ".join(JOINT_TYPES)}')
    ends = joint_ends(spec, where, all_points)
    axis, angle = (1.0, 0.0), 0.0
    if jtype == 'prismatic':
        axis = _vector(_require(spec, 'axis', where), f'{where}.axis')
        norm = math.hypot(*axis)
        if norm == 0.0:
            raise SceneError(f'{where}.axis: got {list(axis)}, expected a non-zero direction')
        axis = (axis[0] / norm, axis[1] / norm)
        angle = math.radians(_number(spec.get('angle_deg', 0.0), f'{where}.angle_deg'))
    elif 'axis' in spec or 'angle_deg' in spec:
        raise SceneError(f'{where}: axis and angle_deg apply to prismatic joints only')
    return Joint(name, jtype, ends[0][0], ends[0][1], ends[1][0], ends[1][1], axis, angle)
