"""
Balancing: one entry point, :func:`balance`, for the command line, the node and recordings.

``balance(rig, method=..., **options)`` returns a :class:`Design`: the balanced scene, its
report (a plain mapping, the same one ``mech-balance balance --json`` prints and the node's
``~/balance`` answers) and the method's own result.  The method is chosen from what the rig
can be balanced by (:attr:`mech_balance.core.rig.Rig.capabilities`), never from its kind:

* ``redistribution``: the certified optimal mass redistribution of seed 001 (planar rigs,
  :func:`mech_balance.balancing.socp.optimize`);
* ``weights``: the RGGR's complete force balance and minimum RMS shaking moment by two
  balancing weights (seed 002, :mod:`mech_balance.balancing.rggr`);
* ``auto`` (the default): the first of those the rig supports.

The modules that solve are imported when a method runs, so importing this package is cheap.
The defaults of every option are :mod:`mech_balance.balancing.defaults`'s.
"""

from dataclasses import dataclass

from mech_balance.balancing.defaults import DEFAULT_WEIGHTS

METHODS = {
    'redistribution': 'mass_redistribution',
    'weights': 'balancing_weights',
}
"""Balancing methods by name, and the rig capability each needs."""


@dataclass
class Design:
    """A balanced design: its scene, its report (plain mapping) and the method's result."""

    scene: object
    report: dict
    method: str
    result: object


def method_for(rig, method='auto'):
    """Return the method that balances ``rig`` (``auto``: the first the rig supports)."""
    caps = rig.capabilities
    if method == 'auto':
        for name, need in METHODS.items():
            if need in caps:
                return name
        raise ValueError(f'scene {rig.name!r}: no balancing method supports this rig')
    if method not in METHODS:
        raise ValueError(f'method: got {method!r}, expected auto or one of '
                         f'{", ".join(METHODS)}')
    if METHODS[method] not in caps:
        supported = [m for m, need in METHODS.items() if need in caps]
        raise ValueError(f'method: got {method!r}, which does not apply to scene '
                         f'{rig.name!r}; expected one of {", ".join(supported) or "none"}')
    return method


def balance(rig, method='auto', **options):
    """
    Balance a rig and return its :class:`Design` (module docstring: methods).

    ``options`` are the method's: those of :func:`mech_balance.balancing.socp.optimize` for
    ``redistribution``; ``samples`` for ``weights``.
    """
    method = method_for(rig, method)
    sc = rig.scene
    if method == 'redistribution':
        from mech_balance.balancing import counterweights, socp
        result = socp.optimize(sc, **options)
        report = result.to_dict()
        report['cost'] = counterweights.cost_of_balancing(sc, result.balanced_scene,
                                                          result.table)
        return Design(result.balanced_scene, report, method, result)
    from mech_balance.analysis import rggr_report
    from mech_balance.balancing import rggr as rggr_balancing
    from mech_balance.conventions import DEFAULT_SAMPLES
    unknown = sorted(set(options) - {'samples'})
    if unknown:
        raise ValueError(f'{unknown[0]}: not an option of the {method} method (it takes '
                         'samples)')
    samples = options.get('samples') or DEFAULT_SAMPLES
    result = rggr_balancing.balance_scene(sc, samples)
    return Design(result.design.scene, rggr_report.balance_report(sc, samples, result=result),
                  method, result)


__all__ = ['balance', 'DEFAULT_WEIGHTS', 'Design', 'method_for', 'METHODS']
