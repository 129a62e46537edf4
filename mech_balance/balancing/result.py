"""
The one result of :func:`mech_balance.balancing.balance`, for every method and kind of rig.

:meth:`Design.to_dict` is the one shape of ``balance --json`` and the node's answer
(docs/cli.md, "JSON output").
"""

from dataclasses import dataclass

SUMMARY_NAME_CHARS = 40
"""Longest scene name in :meth:`Design.summary` (the line stays under 200 characters)."""
FORCE_BALANCE_ROUNDOFF = 1e-9
"""A closed-form force balance is certified when its RMS shaking force after / before <= this."""
STATUS = {0: 'optimal design, certified',
          1: 'design returned, its objective NOT certified',
          2: 'objective certified, but the design is not realizable or a stage failed'}
"""The meaning of :attr:`Design.status` (``success`` is status 0)."""
SCHEMA_KEYS = ('scene', 'kind', 'method', 'success', 'status', 'message', 'objective',
               'objective_name', 'lower_bound', 'certified', 'normalized', 'links', 'table',
               'report')
"""The top-level keys of :meth:`Design.to_dict` (``balance --json``), in order."""


@dataclass
class Design:
    """A balanced design: scene, report, result, verdict; ``figures``: RMS before/after, text."""

    scene: object
    report: dict
    method: str
    result: object
    figures: dict = None

    def __post_init__(self):
        """Read the objective, its lower bound and the verdict from the method's result."""
        res, realizable, failed = self.result, True, False
        cert = getattr(res, 'certificate', None)
        if cert is not None:
            self.objective_name = 'z = w1 f~ + w2 n~ (normalized, Chaudhary & Saha eq. 43)'
            self.objective, self.lower_bound = float(cert.primal), float(cert.lower_bound)
            self.certified = bool(cert.certified)
            failed = bool(cert.failed_stages)
            realizable = bool(getattr(res, 'realizable', True))
        elif hasattr(res, 'moment_rms_lower_bound_Nm'):   # least squares (balancing weights)
            self.objective_name = 'RMS shaking moment, N m (least squares)'
            self.objective = float(res.moment_rms_optimal_Nm)
            self.lower_bound = float(res.moment_rms_lower_bound_Nm)
            self.certified = self.lower_bound <= self.objective
        else:   # a complete force balance in closed form
            force = self.figures['force_N']
            self.objective_name = 'RMS shaking force after / before (complete force balance)'
            self.objective = float(force[1] / max(force[0], 1e-300))
            self.lower_bound = 0.0
            self.certified = self.objective <= FORCE_BALANCE_ROUNDOFF
            realizable = bool(getattr(res, 'realizable', True))
            if not hasattr(res, 'realizable') and hasattr(res, 'links'):
                realizable = all(getattr(d, 'realizable', True) for d in res.links)
        self.realizable = realizable
        self.status = 0 if self.certified and realizable and not failed else \
            1 if not self.certified else 2
        self.success = self.status == 0

    @property
    def message(self):
        """Return the verdict in one line: :data:`STATUS` and the certificate in words."""
        return f'{STATUS[self.status]}: {self.certificate_text}'

    @property
    def links(self):
        """Return the balanced design per moving link: name, mass, mass centre, inertia."""
        out = []
        for lk in getattr(self.scene, 'links', ()):
            centre = tuple(float(x) for x in lk.com_m)
            if hasattr(lk, 'inertia_matrix'):   # a body: the 3x3 tensor in its axes
                inertia = [list(map(float, row)) for row in lk.inertia_matrix()]
            else:   # a planar link: the moment about the plane's normal
                inertia = float(lk.inertia_com_kg_m2)
            out.append({'name': lk.name, 'mass_kg': float(lk.mass_kg),
                        'mass_centre_m': list(centre + (0.0,) * (3 - len(centre))),
                        'inertia_com_kg_m2': inertia})
        return out

    @property
    def masses_kg(self):
        """Return ``{link: mass}`` of the balanced design, kg."""
        return {d['name']: d['mass_kg'] for d in self.links}

    @property
    def mass_centres_m(self):
        """Return ``{link: (x, y, z)}``: each mass centre in its link's frame, m."""
        return {d['name']: tuple(d['mass_centre_m']) for d in self.links}

    @property
    def inertias_kg_m2(self):
        """Return ``{link: inertia about its mass centre}``, kg m^2 (spatial: 3x3, link axes)."""
        return {d['name']: d['inertia_com_kg_m2'] for d in self.links}

    @property
    def table(self):
        """Return the before/after rows of the report (both units: ``*_si`` and not)."""
        return self.report.get('table', [])

    def table_in(self, normalized=False):
        """Return the before/after rows in SI (default) or the papers' normalized units."""
        rows = []
        for r in self.table:
            if 'quantity' not in r:   # a report of another shape: as it is
                rows.append(r)
                continue
            sfx = '' if normalized or 'before_si' not in r else '_si'
            rows.append({'quantity': r['quantity'], 'unit': r['unit' + sfx],
                         'before': r['before' + sfx], 'after': r['after' + sfx],
                         'change_percent': r['change_percent']})
        return rows

    def to_dict(self, normalized=False):
        """Return the one top-level shape of a result (:data:`SCHEMA_KEYS`), table SI or not."""
        from mech_balance.schema import registry
        return {'scene': str(self.report.get('scene', getattr(self.scene, 'name', ''))),
                'kind': registry.kind_of(self.scene).name, 'method': self.method,
                'success': self.success, 'status': self.status, 'message': self.message,
                'objective': self.objective, 'objective_name': self.objective_name,
                'lower_bound': self.lower_bound, 'certified': self.certified,
                'normalized': bool(normalized), 'links': self.links,
                'table': self.table_in(normalized), 'report': self.report}

    @property
    def certificate_text(self):
        """Return the certificate in words (``figures['certificate']``), or ``none``."""
        return (self.figures or {}).get('certificate', 'none')

    def summary(self, certificate=True):
        """Return one line for a terminal: method, RMS before -> after, certificate."""
        f = self.figures or {}
        name = str(self.report.get('scene', ''))
        name = name if len(name) <= SUMMARY_NAME_CHARS else name[:SUMMARY_NAME_CHARS] + '...'
        parts = [f'balanced {name} ({self.method})']
        if 'force_N' in f:
            parts.append(f'RMS shaking force {f["force_N"][0]:.4g} -> {f["force_N"][1]:.4g} N, '
                         f'moment {f["moment_Nm"][0]:.4g} -> {f["moment_Nm"][1]:.4g} N m')
        if certificate:
            parts.append(f'certificate {self.certificate_text}')
        return '; '.join(parts[:1]) + ': ' + '; '.join(parts[1:])
