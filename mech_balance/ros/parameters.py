"""The rig node's parameter part: declaring the table of :mod:`mech_balance.ros.params`."""

from mech_balance import balancing, schema as scene_mod
from mech_balance.ros import conversions as conv, description, params
from mech_balance.ros.balance_service import balance_method
from rcl_interfaces.msg import SetParametersResult


def build_model(name):
    """Load, validate and assemble a scene (the scene loader's checks); ValueError."""
    try:
        return description.twin_for(scene_mod.load(name))  # URDF joints: description
    except OSError as exc:
        raise ValueError(f'scene: cannot read {name!r}: {exc.strerror}') from None
    except ValueError as exc:
        if str(exc).startswith('scene'):
            raise
        raise ValueError(f'scene {name!r}: {exc}') from None


def link_names(model):
    """Return the links with ``balance.links.<link>.*`` options (redistributable rigs)."""
    if not balancing.link_options(model.rig):
        return ()
    return tuple(lk.name for lk in model.scene.links)


def scene_conflicts(values, model):
    """Return ``{name: reason}`` of the link-naming and balancing values ``model`` refutes."""
    links = [lk.name for lk in model.scene.links]
    out = {}
    for name, names in params.named_links(values).items():
        strangers = [n for n in names if n not in links]
        if strangers:
            out[name] = f'names {", ".join(strangers)}, not a link of the scene'
    try:
        method = balance_method(values, model.rig)
    except ValueError as exc:
        out['balance.method'] = str(exc)
        return out
    out.update(range_conflicts(values, model, method))
    return out


def range_conflicts(values, model, method):
    """Return ``{name: reason}`` of the values outside the rig's ``option_ranges``."""
    out = {}
    for option, (low, high) in balancing.option_ranges(model.rig, method).items():
        name = f'balance.{option}'
        outside = [v for v in values[name] if not low <= v <= high]
        if outside:
            out[name] = (f'has {outside[0]:g}, outside [{low:g}, {high:g}] for the '
                         f'{method} of scene {model.scene.name!r}')
    return out


def check_link_options(values, model):
    """Check the per-link balancing options against the links of a redistributable rig."""
    links = link_names(model)
    if links:
        params.check_links(_of_links(values, links), links)


def _of_links(values, links):
    """Return ``values`` without the per-link options of links not in ``links``."""
    own = {f'{params.LINK_PREFIX}{link}.' for link in links}
    return {k: v for k, v in values.items()
            if not k.startswith(params.LINK_PREFIX) or k[:k.rindex('.') + 1] in own}


class NodeParameters:
    """Declare, convert and check the node's parameters (``node``: the rclpy node)."""

    def __init__(self, node):
        self._node = node
        self.values = {}
        self.links = ()
        self.pending_scene = None       # (name, model) checked by the on-set callback
        self.pending_clear = {}         # {name: reason} cleared with that scene

    def declare_all(self):
        """Declare every parameter of the table; return ``{name: checked value}``."""
        for spec in params.PARAMETERS:
            self.declare(spec)
        return self.values

    def declare(self, spec):
        """Declare a parameter; store its checked value, of the declared type (ROS too)."""
        default = None if spec.name.startswith(params.LINK_PREFIX) else spec.default
        declared = self._node.declare_parameter(spec.name, default,
                                                conv.parameter_descriptor(spec))
        value = conv.parameter_value(declared)
        value = spec.default if value is None else params.coerced(spec.name, value)
        self.values[spec.name] = params.check(spec.name, value)
        typed = conv.ros_parameter(spec.name, self.values[spec.name])
        if declared.type_ != typed.type_:  # an integer for a double, an unset link option
            self._node.set_parameters([typed])

    def declare_link_parameters(self, model):
        """Declare ``balance.links.<link>.*`` for the scene's links; drop the others'."""
        self.links = link_names(model)
        options = balancing.link_options(model.rig) if self.links else ()
        wanted = {f'{params.LINK_PREFIX}{link}.{option}': params.link_spec(link, option)
                  for link in self.links for option in options}
        for name in [n for n in self.values if n.startswith(params.LINK_PREFIX)]:
            if name not in wanted:
                if self.values.get(name):
                    self._node.get_logger().info(
                        f'{name}: dropped, scene {model.scene.name!r} has no such link '
                        f'(it had {self.values[name]})')
                self._node.undeclare_parameter(name)
                self.values.pop(name, None)
        for name, spec in wanted.items():
            if name not in self.values:
                self.declare(spec)

    def coerce(self, parameters):
        """Pre-set: convert to the declared type; hold per-link values of links to come."""
        out = []
        for p in parameters:
            try:
                value = conv.parameter_value(p)
                new = params.coerced(p.name, value)
                p = p if new is value else conv.ros_parameter(p.name, new)
                self._hold(p.name, new)
            except Exception:  # noqa: BLE001 - the on-set callback names what is wrong
                pass
            out.append(p)
        return out

    def _hold(self, name, value):
        """Declare a valid per-link option of a link the scene does not have (held)."""
        spec = params.spec_for(name)
        if spec is None or not name.startswith(params.LINK_PREFIX) or \
                self._node.has_parameter(name):
            return
        params.check(name, [] if value is None else value)  # invalid: refused as undeclared
        self.declare(spec)
        link = name[len(params.LINK_PREFIX):].rpartition('.')[0]
        self._node.get_logger().info(
            f'{name}: held for a scene with link {link!r} (scene {self.values["scene"]!r} has '
            'none); it applies once such a scene is set')

    def check(self, parameters, original):
        """On-set: check an update against the values and ``original``; raise ValueError."""
        candidate = dict(self.values)
        model = original
        for p in parameters:
            if params.spec_for(p.name) is None:
                continue  # use_sim_time, qos overrides: rclpy's own
            value = conv.parameter_value(p)
            if value is None and p.name.startswith(params.LINK_PREFIX):
                value = []  # declared unset: the factors
            value = candidate[p.name] = params.check(p.name, value)
            if p.name == 'scene' and value != self.values['scene']:
                model = build_model(value)
                self.pending_scene = (value, model)
        if model is not original:  # a scene switch revalidates, and clears, never blocks
            given = {p.name for p in parameters}
            self.pending_clear = {k: v for k, v in scene_conflicts(candidate, model).items()
                                  if k not in given}
            for name in self.pending_clear:
                candidate[name] = params.BY_NAME[name].default
            candidate = _of_links(candidate, link_names(model))
        check_link_options(candidate, model)
        method = balance_method(candidate, model.rig)
        for name, reason in range_conflicts(candidate, model, method).items():
            raise ValueError(f'{name}: got {list(candidate[name])}, which {reason} '
                             '(balancing.defaults.SPATIAL_MASS_FACTOR_RANGE)')
        params.check_together(candidate)
        return SetParametersResult(successful=True)

    def accepted(self, parameters):
        """Return ``{name: checked value}`` of an accepted update (post-set)."""
        return {p.name: params.check(p.name, conv.parameter_value(p))
                for p in parameters if params.spec_for(p.name) is not None and
                p.value is not None}

    def take_scene(self, name):
        """Return the model of scene ``name`` checked by the on-set callback, or None."""
        pending, self.pending_scene = self.pending_scene, None
        return pending[1] if pending is not None and pending[0] == name else None

    def clear_refuted(self, scene_name):
        """Set the scene-dependent values the new scene refutes to their defaults; log it."""
        cleared, self.pending_clear = self.pending_clear, {}
        for name, reason in cleared.items():
            default = params.BY_NAME[name].default
            self._node.get_logger().info(
                f'scene {scene_name!r}: {name} {self.values[name]!r} {reason}: cleared to '
                f'{default!r}')
            self._node.set_parameters([conv.ros_parameter(name, default)])
