"""
Which ``mech-balance balance`` flags go together: the groups, and the checks before a solve.

Flags are declared once in :data:`mech_balance.balancing.options.OPTIONS`; a flag the
chosen method would ignore is refused, naming it.
"""

import argparse

from mech_balance.balancing import defaults, options
from mech_balance.balancing.defaults import DEFAULT_CASE

SPATIAL_OPTIONS = ('--method', '--extent-factor', '--force-balanced', '--free')
"""Options of spatial rigs alone (mech_balance.balancing.spatial)."""


def _flags(wanted):
    """Return the flags of the options of :data:`.options.OPTIONS` that ``wanted`` accepts."""
    return tuple(opt.flag for opt in options.OPTIONS
                 if opt.flag and opt.flag not in SPATIAL_OPTIONS and opt.key != 'samples'
                 and wanted(opt))


OPTIMIZE_OPTIONS = _flags(lambda opt: 'redistribution' in opt.methods)
"""Options of the seed-001 optimization: rejected with --analytic and for spatial rigs."""
ANALYTIC_OPTIONS = ('--mass-factor', '--keep-centroidal')
"""Options of --analytic alone: rejected without it (the command line's own)."""
COUNTERWEIGHT_OPTIONS = _flags(lambda opt: opt.methods == options.COUNTERWEIGHTS and
                               opt.key in defaults.COUNTERWEIGHT_RANGES and
                               opt.default is not None)
"""Options of --counterweights alone with a number default, each in a range of its own."""
COUNTERWEIGHT_PLACEMENT = _flags(lambda opt: opt.methods == options.COUNTERWEIGHTS and
                                 opt.key != 'links' and
                                 opt.flag not in COUNTERWEIGHT_OPTIONS) + ('--build-sheet',)
"""Options of --counterweights alone that have no number default (checked by the solver)."""
COUNTERWEIGHT_SHARED = _flags(lambda opt: set(options.OPTIMIZERS) <= set(opt.methods))
"""Options of the optimization that --counterweights uses too (the rest it rejects)."""
PLANAR_OPTIONS = OPTIMIZE_OPTIONS + ANALYTIC_OPTIONS + COUNTERWEIGHT_OPTIONS + \
    COUNTERWEIGHT_PLACEMENT + ('--analytic', '--counterweights', '--model')
"""Options of the planar balancing (spatial rigs take only :data:`SPATIAL_SHARED` of them)."""
CLEARANCE_KEYS = ('clearance_margin_m', 'clearance')
"""Options of the spatial counterweights that :func:`mech_balance.balancing.balance` reads
besides :data:`mech_balance.balancing.SPATIAL_OPTIONS` (the clearance check of the spheres)."""


def _spatial_shared():
    from mech_balance import balancing
    keys = set(CLEARANCE_KEYS).union(*balancing.SPATIAL_OPTIONS.values())
    return _flags(lambda opt: opt.key in keys)


SPATIAL_SHARED = _spatial_shared()
"""Options of the planar balancing that spatial rigs (body kinematics) take too: those of
:data:`mech_balance.balancing.SPATIAL_OPTIONS` and the clearance."""
SPATIAL_ONLY_FOR = {'--free': 'force_balance', '--force-balanced': 'redistribution',
                    '--extent-factor': 'redistribution'}
"""The spatial method each of the spatial options applies to."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Append ``(default: ...)`` unless the default is None or False (said in words, or off)."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False or action.default == []:
            return action.help
        if isinstance(action.default, tuple):   # the values as they are typed
            return f'{action.help} (default: {" ".join(f"{v:g}" for v in action.default)})'
        return super()._get_help_string(action)


def dest(flag):
    """Return the argparse destination of ``flag`` (``--max-thickness``: ``max_thickness``)."""
    return flag.lstrip('-').replace('-', '_')


def add_weight_and_case(p, when='', case_when=None):
    """Add ``--weights W1 W2`` and ``--case a|b`` (default None), ``when`` prefixing their help."""
    from mech_balance.cli import main as cli
    case_when = when if case_when is None else case_when
    w1, w2 = defaults.DEFAULT_WEIGHTS
    p.add_argument('--weights', nargs=2, type=cli.weight, default=None, metavar=('W1', 'W2'),
                   help=f'{when}weights on the RMS normalized shaking force and shaking '
                        f'moment, Chaudhary & Saha eq. 43 (default: {w1:g} {w2:g}, their '
                        'case (2))')
    p.add_argument('--case', choices=defaults.CASES, default=None,
                   help=f'{case_when}Chaudhary & Saha sec. 4.1.2: a = point masses of any '
                        'sign, b = non-negative point masses (counterweights) (default: '
                        f'{DEFAULT_CASE})')


def given(args, flags):
    """Return those of ``flags`` that the command line set to other than their defaults."""
    def plain(value):
        return tuple(value) if isinstance(value, (list, tuple)) else value
    return [f for f in flags
            if plain(getattr(args, dest(f))) != plain(args.option_defaults[f])]


def check_planar(args):
    """Raise ValueError for a flag the chosen planar method would ignore (no scene needed)."""
    if args.counterweights is not None:
        return _check_counterweights(args)
    given_cw = given(args, COUNTERWEIGHT_OPTIONS + COUNTERWEIGHT_PLACEMENT)
    if given_cw:
        raise ValueError(f'{given_cw[0]} applies with --counterweights only, expected '
                         f'--counterweights LINK[,LINK...] or no {given_cw[0]}')
    if args.model != 'three-point' and (args.analytic or args.paper_constraints or
                                        args.torque_weight or args.reaction_weight):
        raise ValueError('--model two-point: Chaudhary & Saha eqs. B.1-B.3 have their own '
                         'bounds and weights w1, w2 only; expected no --analytic, '
                         '--paper-constraints, --torque-weight or --reaction-weight with it')
    ignored = given(args, OPTIMIZE_OPTIONS if args.analytic else ANALYTIC_OPTIONS)
    if ignored and args.analytic:
        raise ValueError(f'{ignored[0]} applies to the optimization, not to --analytic; '
                         f'expected no {ignored[0]} with --analytic')
    if ignored:
        raise ValueError(f'{ignored[0]} applies with --analytic only, expected --analytic or '
                         f'no {ignored[0]}')


def _check_counterweights(args):
    import math
    from mech_balance import identifiers
    identifiers.check_name_list(args.counterweights, '--counterweights')  # as the node's
    if args.analytic:
        raise ValueError('--counterweights: a method of its own, expected no --analytic '
                         'with --counterweights')
    ignored = given(args, tuple(f for f in OPTIMIZE_OPTIONS + ANALYTIC_OPTIONS
                                if f not in COUNTERWEIGHT_SHARED))
    if args.model != 'three-point':
        ignored.insert(0, '--model')
    if ignored:
        raise ValueError(f'{ignored[0]} does not apply to --counterweights; expected no '
                         f'{ignored[0]} with --counterweights')
    for flag in COUNTERWEIGHT_OPTIONS:
        value = getattr(args, dest(flag))
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f'{flag}: got {value:g}, expected a finite number > 0')
        defaults.check_counterweight_option(options.BY_FLAG[flag].key, value, flag)
    if args.no_clearance and given(args, ('--clearance-margin',)):
        raise ValueError('--clearance-margin: no clearance is asked for with '
                         '--no-clearance; expected one of them')
    options.check_args(args, ('clearance_margin_m', 'max_overhang_m'))
    if args.max_rim_radius_factor is not None:
        defaults.check_counterweight_option('max_rim_radius_factor', args.max_rim_radius_factor,
                                            '--max-rim-radius-factor')


def check_spatial(args, rig, method):
    """Raise ValueError for a flag the spatial ``method`` would ignore or a value out of range."""
    from mech_balance import balancing
    if method == 'weights':
        ignored = [f for f in given(args, SPATIAL_SHARED + SPATIAL_OPTIONS) if f != '--method']
        if ignored:
            raise ValueError(f'{ignored[0]}: not an option of the method weights (Hedaya, '
                             f'which takes --samples only); expected no {ignored[0]}, or '
                             '--method redistribution, force-balance or counterweights')
        return
    if method == 'redistribution':
        defaults.check_range('--extent-factor', args.extent_factor,
                             *defaults.EXTENT_FACTOR_RANGE)
        for key, (low, high) in balancing.option_ranges(rig, method).items():
            for value in getattr(args, key):
                defaults.check_range(f'--{key.replace("_", "-")}', value, low, high)
    elif method == 'counterweights' and not args.counterweights:
        raise ValueError('--method counterweights: expected --counterweights LINK[,LINK...]')
    for flag, wanted in SPATIAL_ONLY_FOR.items():
        if given(args, (flag,)) and method != wanted:
            raise ValueError(f'{flag}: applies to --method {wanted.replace("_", "-")}, got '
                             f'method {method}; expected no {flag}')
