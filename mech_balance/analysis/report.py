"""What ``mech-balance analyze`` prints: one :class:`Report` per scene, whatever its kind."""

from dataclasses import dataclass, field


@dataclass
class Report:
    """An analysis report: the text table, its JSON form and the warnings to show."""

    text: str
    data: dict
    warnings: list = field(default_factory=list)


ANALYSIS_KEYS = ('scene', 'kind', 'samples', 'crank_speed_rad_s', 'crank_acceleration_rad_s2',
                 'moment_point_m', 'outputs', 'normalized', 'rows', 'worst_residual',
                 'worst_condition', 'near_singular', 'near_singular_condition', 'extras')
"""The top-level keys of ``mech-balance analyze --json``, for every kind (docs/cli.md); a row
is ``{quantity, unit, rms, max_abs, kind}``; what only one kind reports is under ``extras``."""
SI_UNITS = {'force': 'N', 'moment': 'N*m', 'energy': 'J'}
"""The unit of each dimension of a table row (:data:`mech_balance.schema.scene.SERIES`)."""
NORMALIZED_UNITS = {'force': 'm1*a1*w^2', 'moment': 'm1*a1^2*w^2', 'energy': 'm1*a1^2*w^2'}
"""The same in the papers' normalized view (seed 001 sec. 3.4)."""


def analysis_dict(sc, rig, samples, normalized, rows, worst_residual, worst_condition,
                  near_singular, near_singular_condition, extras):
    """Return the ``analyze --json`` mapping (:data:`ANALYSIS_KEYS`), the same for every kind."""
    from mech_balance.schema import registry
    return {'scene': sc.name, 'kind': registry.kind_of(sc).name, 'samples': samples,
            'crank_speed_rad_s': sc.crank_speed_rad_s,
            'crank_acceleration_rad_s2': sc.crank_acceleration_rad_s2,
            'moment_point_m': [float(x) for x in rig.moment_point_m],
            'outputs': list(sc.outputs), 'normalized': bool(normalized), 'rows': rows,
            'worst_residual': worst_residual, 'worst_condition': worst_condition,
            'near_singular': near_singular, 'near_singular_condition': near_singular_condition,
            'extras': extras}
