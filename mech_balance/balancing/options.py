"""
The balancing options, each declared once: the command line's and the node's from one table.

:data:`OPTIONS`; :func:`from_params` and :func:`from_args` read either surface.
"""

from dataclasses import dataclass
import math

from mech_balance import conventions, identifiers
from mech_balance.balancing import defaults
from mech_balance.schema import safe_yaml
from mech_balance.schema.scene import MAX_PLANE_OFFSET_M

STRING, DOUBLE, INTEGER, BOOL, DOUBLE_ARRAY = 'string', 'double', 'integer', 'bool', \
    'double_array'
MAX_COUNTERWEIGHT_VALUE = 1e6
"""Largest counterweight density (kg/m^3), thickness (m) or factor a parameter accepts."""
MAX_MARGIN = 0.999
"""Largest realizability margin (the balancing requires margin < 1)."""
REDISTRIBUTION = ('redistribution',)
COUNTERWEIGHTS = ('counterweights',)
OPTIMIZERS = REDISTRIBUTION + COUNTERWEIGHTS
ALL_METHODS = ('redistribution', 'counterweights', 'analytic', 'weights', 'force_balance')


@dataclass(frozen=True)
class Option:
    """One balancing option (module docstring); ``param``/``flag`` None if a surface lacks it."""

    key: str
    param: str
    flag: str
    value_type: str
    default: object
    description: str
    methods: tuple = OPTIMIZERS
    bounds: tuple = None
    choices: tuple = None
    check: object = None      # callable(name, value): ValueError naming ``name``
    rule: str = ''
    param_default: object = None
    to_option: object = None  # parameter value -> balance() value
    cli: dict = None
    flag_help: str = None

    @property
    def dest(self):
        """Return the argparse destination of :attr:`flag`."""
        return self.flag.lstrip('-').replace('-', '_')

    def validate(self, name, value):
        """Raise ValueError unless ``value`` lies in the bounds and choices and passes check."""
        if self.bounds is not None and not self.bounds[0] <= value <= self.bounds[1]:
            raise ValueError(f'{name}: got {value!r}, expected {self.bounds[0]:g} <= value <= '
                             f'{self.bounds[1]:g}')
        if self.choices is not None and value not in self.choices:
            raise ValueError(f'{name}: got {value!r}, expected one of '
                             f'{", ".join(self.choices)}')
        if self.check is not None:
            self.check(name, value)


def check_weights(name, value):
    """Accept [w1, w2] >= 0, not both 0 (weights of the RMS shaking force and moment)."""
    top = conventions.MAX_WEIGHT
    if len(value) != 2 or not all(math.isfinite(v) and 0.0 <= v <= top for v in value):
        raise ValueError(f'{name}: got {list(value)}, expected [w1, w2] with '
                         f'0 <= w1, w2 <= {top:g} (Chaudhary & Saha eq. 43; the upper bound is '
                         'fixed)')
    if value[0] + value[1] == 0.0:
        raise ValueError(f'{name}: got [0, 0], expected at least one positive weight')


def _factors(ratio_range):
    def check(name, value):
        """Accept [low, high] factors of the original value, 0 < low <= high, in range."""
        if len(value) != 2 or not all(math.isfinite(v) for v in value) or \
                not 0.0 < value[0] <= value[1]:
            raise ValueError(f'{name}: got {list(value)}, expected [low, high] with '
                             '0 < low <= high (factors of the original link value)')
        for v in value:
            defaults.check_range(name, v, *ratio_range)
    return check


def parse_link_bounds(name, text, unit):
    """
    Return ``{link: (min, max)}`` from a ``balance.*_bounds`` text, or None when empty.

    The text is a YAML mapping such as ``{crank: [0.3, 1.5], rocker: [5e-1, null]}`` in ``unit``.
    """
    if not text.strip():
        return None
    data = safe_yaml.loads(text, name)  # bounded: depth, size, aliases (a YamlError)
    if not isinstance(data, dict) or not data:
        raise ValueError(f'{name}: got {text!r}, expected a mapping link: [min, max] in {unit}')
    out = {}
    for link, pair in data.items():
        ok = isinstance(link, str) and isinstance(pair, (list, tuple)) and len(pair) == 2
        if ok:
            lo, hi = pair
            ok = all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)
                                   and math.isfinite(v)) for v in (lo, hi))
            ok = ok and lo is not None and lo > 0.0 and (hi is None or hi >= lo)
        if not ok:
            raise ValueError(f'{name}.{link}: got {pair!r}, expected [min, max] in {unit} with '
                             '0 < min <= max (max may be null: no upper bound)')
        defaults.check_bound_pair(f'{name}.{link}', lo, hi, unit)
        out[link] = (float(lo), None if hi is None else float(hi))
    return out


def split_links(text):
    """Return the link names of a comma-separated text (``balance.fixed_links``)."""
    return [n.strip() for n in text.split(',')] if text.strip() else []


def _link_bounds(unit):
    def check(name, value):
        """Accept empty or a YAML mapping link: [min, max] in SI (max may be null)."""
        parse_link_bounds(name, value, unit)
    return check


def _link_list(name, value):
    """Accept empty or comma-separated link names, each once."""
    identifiers.check_name_list(value, name)


def _counterweight(option):
    def check(name, value):
        """Accept a number in the option's range (as ``mech-balance balance --counterweights``)."""
        if not 0.0 < value <= MAX_COUNTERWEIGHT_VALUE:
            raise ValueError(f'{name}: got {value!r}, expected a number > 0 and at most '
                             f'{MAX_COUNTERWEIGHT_VALUE:g}')
        defaults.check_counterweight_option(option, value, name)
    lowest, highest = defaults.COUNTERWEIGHT_RANGES[option]
    return {'check': check, 'rule': f'in [{lowest:g}, {highest:g}]'}


def _samples(name, value):
    """Accept 0 (the scene's samples) or an integer >= 4."""
    if 0 < value < 4:
        raise ValueError(f"{name}: got {value}, expected 0 (the scene's) or an integer >= 4")


def _range_text(key):
    lowest, highest = defaults.COUNTERWEIGHT_RANGES[key]
    return f'; range {lowest:g} to {highest:g}'


def _overhang(name, value):
    """Accept a positive overhang (m); a parameter's 0 is no bound, a flag's is refused."""
    if value <= 0.0 and (name.startswith('--') or value < 0.0):
        raise ValueError(f'{name}: got {value!r}, expected a number of metres > 0'
                         + ('' if name.startswith('--') else ' or 0 (no bound)'))


_BOUNDS_RULE = ("empty or the quoted YAML '{link: [min, max]}', 0 < min <= max, max may be "
                'null')
_tuple = tuple   # parameter arrays become the tuples balance() takes


def _none_if_zero(value):
    return value or None


OPTIONS = (
    Option('weights', 'balance.weights', '--weights', DOUBLE_ARRAY, defaults.DEFAULT_WEIGHTS,
           'Weights [w1, w2] of the RMS shaking force and moment in the balancing objective '
           '(Chaudhary & Saha eq. 43; mech-balance balance --weights).',
           check=check_weights,
           rule='two numbers >= 0, not both 0', to_option=_tuple,
           cli={'nargs': 2, 'metavar': ('W1', 'W2')},
           flag_help='weights on the RMS normalized shaking force and shaking moment, '
                     'Chaudhary & Saha eq. 43; their case (2) is the default'),
    Option('case', 'balance.case', '--case', STRING, defaults.DEFAULT_CASE,
           'a: point masses of any sign; b: non-negative point masses (counterweights).',
           methods=REDISTRIBUTION, choices=defaults.CASES,
           flag_help='Chaudhary & Saha sec. 4.1.2: a = point masses of any sign, b = '
                     'non-negative point masses (counterweights)'),
    Option('realizable', 'balance.realizable', '--no-realizable', BOOL, True,
           'Require every balanced link to be a realizable body (centroidal inertia >= '
           'balance.margin x I_O); false is --no-realizable.', methods=REDISTRIBUTION,
           cli={'action': 'store_false'},
           flag_help='drop the realizability constraint (centroidal inertia >= margin x I_O)'),
    Option('centroidal_margin', 'balance.margin', '--margin', DOUBLE, defaults.CENTROIDAL_MARGIN,
           'Realizability margin: centroidal inertia >= margin x inertia about the link '
           'origin.', methods=REDISTRIBUTION, bounds=(0.0, MAX_MARGIN),
           flag_help='realizability margin: centroidal inertia >= MARGIN x inertia about the link '
                     'origin'),
    Option('paper_constraints', 'balance.paper_constraints', '--paper-constraints', BOOL,
           False, "Solve exactly Chaudhary & Saha eqs. 50/53 (the paper's bounds, no "
           'realizability); other bound options must keep their defaults.', methods=REDISTRIBUTION,
           cli={'action': 'store_true'},
           flag_help="reproduce Chaudhary & Saha's problem exactly (eqs. 50/53: masses in "
                     '[1, 5] x original, l in [0.5, 1.5] x original, no realizability '
                     'constraint)'),
    Option('mass_factors', 'balance.mass_factors', '--mass-factors', DOUBLE_ARRAY,
           defaults.PAPER_MASS_FACTORS,
           'Link mass bounds [low, high] as factors of the original link mass (eq. 50b).',
           methods=REDISTRIBUTION, check=_factors(defaults.BOUND_RATIO_RANGE),
           rule='[low, high], 0 < low <= high, each in [1e-06, 1e+06]', to_option=_tuple,
           cli={'nargs': 2, 'metavar': ('LO', 'HI')},
           flag_help='link mass bounds as factors of the original masses (range '
                     f'{defaults.BOUND_RATIO_RANGE[0]:g} to {defaults.BOUND_RATIO_RANGE[1]:g}; '
                     f'spatial redistribution {defaults.SPATIAL_MASS_FACTOR_RANGE[0]:g} to '
                     f'{defaults.SPATIAL_MASS_FACTOR_RANGE[1]:g})'),
    Option('distance_factors', 'balance.distance_factors', '--distance-factors', DOUBLE_ARRAY,
           defaults.PAPER_DISTANCE_FACTORS,
           'Point-mass distance bounds [low, high] as factors of the original '
           'l = sqrt(I_O/m) (eq. 50c).', methods=REDISTRIBUTION,
           check=_factors(defaults.DISTANCE_RATIO_RANGE),
           rule='[low, high], 0 < low <= high, each in [0.01, 100]', to_option=_tuple,
           cli={'nargs': 2, 'metavar': ('LO', 'HI')},
           flag_help='point-mass distance bounds as factors of the original l = sqrt(I_O/m) '
                     f'(range {defaults.DISTANCE_RATIO_RANGE[0]:g} to '
                     f'{defaults.DISTANCE_RATIO_RANGE[1]:g})'),
    Option('mass_bounds', 'balance.mass_bounds', None, STRING, None,
           'Per-link mass bounds in kg overriding the factors, YAML text, quoted on the command '
           'line: ros2 param set /rig balance.mass_bounds "\'{crank: [0.3, 1.6]}\'" (the older '
           'form of the typed balance.links.crank.mass_bounds "[0.3, 1.6]").',
           methods=REDISTRIBUTION, check=_link_bounds('kg'), rule=_BOUNDS_RULE,
           param_default=''),
    Option('distance_bounds', 'balance.distance_bounds', None, STRING, None,
           'Per-link point-mass distance bounds in m overriding the factors, YAML text, quoted '
           'on the command line: "\'{crank: [0.02, null]}\'" (the older form of the typed '
           'balance.links.crank.distance_bounds "[0.02]").', methods=REDISTRIBUTION,
           check=_link_bounds('m'), rule=_BOUNDS_RULE, param_default=''),
    Option('torque_weight', 'balance.torque_weight', '--torque-weight', DOUBLE, 0.0,
           'Extra weight on the RMS normalized driving torque.',
           bounds=(0.0, conventions.MAX_WEIGHT)),
    Option('reaction_weight', 'balance.reaction_weight', '--reaction-weight', DOUBLE, 0.0,
           'Extra weight on the sum of the RMS normalized bearing forces.',
           bounds=(0.0, conventions.MAX_WEIGHT)),
    Option('max_added_mass_kg', 'balance.max_added_mass', '--max-added-mass', DOUBLE, None,
           'Cap on the total added mass, kg (over the original total); negative: no cap.',
           methods=REDISTRIBUTION, bounds=(-1.0, 1e6), param_default=-1.0,
           to_option=lambda v: None if v < 0.0 else v, cli={'metavar': 'KG'},
           flag_help='cap on the total added mass (kg, over the original total)'),
    Option('fixed_links', 'balance.fixed_links', '--fix', STRING, (),
           'Comma-separated links kept as they are (e.g. "crank,rocker"); empty: none.',
           methods=REDISTRIBUTION, check=_link_list, rule='links of the scene',
           param_default='', to_option=lambda v: tuple(split_links(v)),
           cli={'action': 'append', 'metavar': 'LINK'},
           flag_help='keep this link as it is (repeatable)'),
    Option('samples', 'balance.samples', '--samples', INTEGER, None,
           "Crank angles per revolution in the balancing objective; 0: the scene's samples "
           '(usually 360).', methods=ALL_METHODS, bounds=(0, conventions.MAX_SAMPLES),
           check=_samples, rule='0 or >= 4', param_default=0, to_option=_none_if_zero,
           flag_help="crank angles per revolution (default: the scene's, usually 360)"),
    Option('links', 'balance.counterweight_links', '--counterweights', STRING, (),
           'Counterweights: comma-separated links that each gain one disc (e.g. '
           '"crank,rocker"); needed by balance.method counterweights.',
           methods=COUNTERWEIGHTS, check=_link_list, rule='links of the scene, each once',
           param_default='', to_option=lambda v: tuple(split_links(v)),
           cli={'metavar': 'LINK[,LINK...]', 'default': None},
           flag_help='add-only counterweights instead: each listed link keeps its mass, mass '
                     'centre and inertia and gains one solid disc (certified SOCP); every other '
                     'link is untouched'),
    Option('density_kg_m3', 'balance.density', '--density', DOUBLE, defaults.DEFAULT_DENSITY_KG_M3,
           'Counterweights: disc material density, kg/m^3 (steel).', methods=COUNTERWEIGHTS,
           **_counterweight('density_kg_m3'), cli={'metavar': 'KG_M3'},
           flag_help='--counterweights: disc material density (kg/m^3; steel)'
                     + _range_text('density_kg_m3')),
    Option('max_thickness_m', 'balance.max_thickness', '--max-thickness', DOUBLE,
           defaults.DEFAULT_MAX_THICKNESS_M, 'Counterweights: thickest disc, m.',
           methods=COUNTERWEIGHTS, **_counterweight('max_thickness_m'), cli={'metavar': 'M'},
           flag_help='--counterweights: thickest disc (m)' + _range_text('max_thickness_m')),
    Option('max_radius_factor', 'balance.max_radius_factor', '--max-radius-factor', DOUBLE,
           defaults.DEFAULT_MAX_RADIUS_FACTOR,
           "Counterweights: disc centre at most this factor times the distance from the link's "
           'origin to its farthest joint point.', methods=COUNTERWEIGHTS,
           **_counterweight('max_radius_factor'), cli={'metavar': 'F'},
           flag_help="--counterweights: disc centre at most F x the distance from the link's "
                     'origin to its farthest joint point' + _range_text('max_radius_factor')),
    Option('max_mass_factor', 'balance.max_mass_factor', '--max-mass-factor', DOUBLE,
           defaults.DEFAULT_MAX_MASS_FACTOR,
           "Counterweights: disc mass at most this factor times the link's own mass.",
           methods=COUNTERWEIGHTS, **_counterweight('max_mass_factor'), cli={'metavar': 'F'},
           flag_help="--counterweights: disc mass at most F x the link's mass"
                     + _range_text('max_mass_factor')),
    Option('max_gyration_factor', 'balance.max_gyration_factor', '--max-gyration-factor',
           DOUBLE, defaults.DEFAULT_MAX_GYRATION_FACTOR,
           "Counterweights: the disc's radius of gyration about the link origin at most this "
           "factor times the link's joint reach.", methods=COUNTERWEIGHTS,
           **_counterweight('max_gyration_factor'), cli={'metavar': 'F'},
           flag_help="--counterweights: the disc's radius of gyration about the link origin at "
                     "most F x the link's farthest joint distance (keeps a vanishing disc from "
                     'carrying inertia; above 100 the program is ill-posed)'
                     + _range_text('max_gyration_factor')),
    Option('clearance_margin_m', 'balance.clearance_margin', '--clearance-margin', DOUBLE,
           defaults.DEFAULT_CLEARANCE_MARGIN_M,
           'Counterweights: the least clearance between a counterweight (disc, shaft, web) and '
           'any other body over the cycle, m; the discs go to layers of their own beyond the '
           'linkage and the price of clearance is reported (docs/build.md).',
           methods=COUNTERWEIGHTS, bounds=(0.0, defaults.MAX_CLEARANCE_MARGIN_M),
           cli={'metavar': 'M'},
           flag_help='--counterweights: the least clearance between a counterweight (disc, '
                     'shaft, web) and any other body over the cycle, in m; the discs go to '
                     'layers of their own beyond the linkage and the price of clearance is '
                     'printed (docs/build.md)'),
    Option('clearance', 'balance.clearance', '--no-clearance', BOOL, True,
           'Counterweights: a collision-free design (balance.clearance_margin); false is '
           "--no-clearance: the certified convex optimum as is, discs in their links' planes.",
           methods=COUNTERWEIGHTS, cli={'action': 'store_false'},
           flag_help='--counterweights: the certified convex optimum as is (discs in their '
                     "links' planes or --planes), no collision-free design"),
    Option('disc_side', 'balance.disc_side', '--disc-side', STRING, 'auto',
           'Counterweights: the side of the linkage the discs go to (above: +z, below: -z; '
           'auto: the side with room, per disc).', methods=COUNTERWEIGHTS, choices=defaults.SIDES,
           flag_help='--counterweights: the side of the linkage the discs go to (+z above, '
                     '-z below; auto: the side with room, per disc)'),
    Option('max_overhang_m', 'balance.max_overhang', '--max-overhang', DOUBLE, None,
           "Counterweights: a disc's outer face at most this beyond its link's plane, m; 0: "
           "no bound but the scene's plane_m limit.", methods=COUNTERWEIGHTS,
           bounds=(0.0, MAX_PLANE_OFFSET_M), check=_overhang, rule='0 (no bound) or > 0',
           param_default=0.0, to_option=_none_if_zero, cli={'metavar': 'M'},
           flag_help="--counterweights: a disc's outer face at most M beyond its link's "
                     "plane (m; default: no bound but the scene's plane_m limit)"),
    # the options without a node parameter: their description is the flag's help
    Option('extent_factor', None, '--extent-factor', DOUBLE, 1.5,
           "spatial redistribution: RMS distance of each body's mass from its origin at most F x "
           f'its reach (farthest drawn point); range {defaults.EXTENT_FACTOR_RANGE[0]:g} to '
           f'{defaults.EXTENT_FACTOR_RANGE[1]:g}', methods=REDISTRIBUTION,
           bounds=defaults.EXTENT_FACTOR_RANGE, cli={'metavar': 'F'}),
    Option('planes', None, '--planes', STRING, '',
           "--counterweights: a disc's plane, its mid-plane's offset along z from its link's "
           "plane in m (default: each link's own plane, 0); bodies whose slabs along z overlap "
           'share a plane and are checked for clearance over the cycle', methods=COUNTERWEIGHTS,
           cli={'metavar': 'LINK=Z[,LINK=Z...]'}),
    Option('max_rim_radius_factor', None, '--max-rim-radius-factor', DOUBLE, None,
           "--counterweights: the whole disc inside F x the link's joint reach of the link's "
           'origin (a convex constraint of the program; default: no bound)'
           + _range_text('max_rim_radius_factor'), methods=COUNTERWEIGHTS, cli={'metavar': 'F'}),
    Option('force_balanced', None, '--force-balanced', BOOL, False,
           'Spatial redistribution: impose complete force balance (falls back to the least '
           'RMS shaking force, with a note, when impossible).', methods=REDISTRIBUTION,
           cli={'action': 'store_true'}),
    Option('free', None, '--free', STRING, None,
           '--method force-balance: a body that may change (repeatable; default all).',
           methods=('force_balance',), cli={'action': 'append', 'metavar': 'LINK'}),
)
"""Every balancing option a user sets (module docstring), in the node's declaration order."""

BY_KEY = {opt.key: opt for opt in OPTIONS}
BY_FLAG = {opt.flag: opt for opt in OPTIONS if opt.flag}


def param_default(opt):
    """Return the default of ``opt``'s parameter (its own form where it differs)."""
    if opt.param_default is not None:
        return opt.param_default
    return list(opt.default) if isinstance(opt.default, tuple) else opt.default


def flag_default(opt):
    """Return the default of ``opt``'s command-line flag (``--no-realizable``: False)."""
    if opt.cli and opt.cli.get('action') in ('store_false', 'store_true'):
        return False
    if opt.cli and opt.cli.get('action') == 'append':
        return []
    return opt.default


def add_arguments(parser, keys, types=None):
    """Add the flags of the options ``keys`` to a parser (``types``: key -> argparse type)."""
    base = {DOUBLE: float, DOUBLE_ARRAY: float, INTEGER: int, STRING: str}
    for key in keys:
        opt = BY_KEY[key]
        kw = dict(opt.cli or {})
        default = kw.pop('default', flag_default(opt))
        if kw.get('action') == 'store_false':   # a --no-X flag: True when given (from_args)
            kw['action'] = 'store_true'
        if kw.get('action') not in ('store_true', 'store_false'):
            kw['type'] = (types or {}).get(key, base[opt.value_type])
        if opt.choices is not None:
            kw['choices'] = opt.choices
        parser.add_argument(opt.flag, default=default, dest=opt.dest,
                            help=opt.flag_help or opt.description, **kw)


def from_params(values, method):
    """Return ``balance()``'s keyword arguments for ``method`` from the node's parameters."""
    out = {}
    for opt in OPTIONS:
        if opt.param is None or method not in opt.methods or opt.param not in values:
            continue
        value = values[opt.param]
        out[opt.key] = opt.to_option(value) if opt.to_option else value
    for key, unit in (('mass_bounds', 'kg'), ('distance_bounds', 'm')):
        if key not in out:
            continue
        merged = dict(parse_link_bounds(f'balance.{key}', values[f'balance.{key}'], unit)
                      or {})
        for name, value in values.items():
            if name.startswith(LINK_PREFIX) and name.endswith(f'.{key}') and value:
                link = name[len(LINK_PREFIX):-len(key) - 1]
                merged[link] = (float(value[0]), float(value[1]) if len(value) == 2 else None)
        out[key] = merged or None
    return _clearance(out)


def from_args(args, method, keys=None):
    """Return ``balance()``'s keyword arguments for ``method`` from parsed flags (``keys``)."""
    out = {}
    for opt in OPTIONS:
        if opt.flag is None or method not in opt.methods or \
                (keys is not None and opt.key not in keys):
            continue
        value = getattr(args, opt.dest)
        action = (opt.cli or {}).get('action')
        if action in ('store_true', 'store_false'):
            value = bool(value) if action == 'store_true' else not value
        elif opt.key == 'links':
            value = tuple(split_links(value or ''))
        elif isinstance(value, list):
            value = tuple(value) or opt.default
        out[opt.key] = opt.default if value is None else value
    return _clearance(out)


def _clearance(out):
    """Turn ``clearance`` off (``--no-clearance``) into ``clearance_margin_m`` None."""
    if not out.pop('clearance', True):
        out['clearance_margin_m'] = None
    return out


def check_args(args, keys):
    """Check every given flag of ``keys`` with its option's check, naming the flag."""
    for key in keys:
        opt = BY_KEY[key]
        value = getattr(args, opt.dest)
        if value is None or (opt.cli or {}).get('action'):
            continue
        opt.validate(opt.flag, list(value) if isinstance(value, (list, tuple)) else value)


LINK_PREFIX = 'balance.links.'
"""Per-link balancing options are ``balance.links.<link>.<option>``, declared from the scene."""
LINK_OPTIONS = {'mass_bounds': ('kg', 'balance.mass_bounds', 'link mass bounds'),
                'distance_bounds': ('m', 'balance.distance_bounds',
                                    'point-mass distance bounds')}
"""Per-link options: unit, the older text parameter they replace, what they bound."""
