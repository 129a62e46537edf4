"""
What ``mech-balance analyze`` prints: one :class:`Report` per scene, whatever its kind.

Each kind's ``analyze`` implementation (registered in :mod:`mech_balance.schema.registry`)
returns one; the command prints ``text`` or, with ``--json``, ``data``, and ``warnings`` on
standard error.
"""

from dataclasses import dataclass, field


@dataclass
class Report:
    """An analysis report: the text table, its JSON form and the warnings to show."""

    text: str
    data: dict
    warnings: list = field(default_factory=list)
