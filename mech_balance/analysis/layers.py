"""The layered model of a planar rig as built (docs/build.md#the-layered-model)."""

from dataclasses import dataclass

from mech_balance.core.planar import drawn

STACK_EXTRA_M = 1e-6
"""Discs are stacked this much beyond the margin along z (m): round-off in the planes' sums
then never brings two layers closer than the margin."""


@dataclass(frozen=True)
class Layer:
    """One body's plate: mid-plane ``z_m``, ``thickness_m`` along z, bars ``bar_width_m``."""

    z_m: float
    thickness_m: float
    bar_width_m: float


@dataclass(frozen=True)
class Layers:
    """The rig as built (SI): a :class:`Layer` per body, the pins' radius and bosses' length."""

    layers: dict           # body name -> Layer
    pin_radius_m: float
    boss_length_m: float

    @classmethod
    def of(cls, scene, linkage):
        """Return the layers of a planar scene (its ``build:`` over the drawn defaults)."""
        spec = scene.build or {}
        scale = linkage.length_scale
        pitch = spec.get('layer_pitch_m', drawn.LAYER * scale)
        width = spec.get('bar_width_m', drawn.BAR_WIDTH * scale)
        thick = spec.get('bar_thickness_m', drawn.BAR_THICKNESS * scale)
        pin = spec.get('pin_radius_m', drawn.PIN_RADIUS * scale)
        boss = spec.get('boss_length_m', drawn.PIN_LENGTH * thick)
        per = spec.get('layers', {})
        layers = {}
        for k, name in enumerate(linkage.body_names):
            own = per.get(name, {})
            layers[name] = Layer(own.get('z_m', pitch * k), own.get('thickness_m', thick),
                                 own.get('bar_width_m', width))
        return cls(layers, pin, boss)

    def z_m(self, body):
        """Return the mid-plane of a body (m)."""
        return self.layers[body].z_m

    def slab(self, body):
        """Return ``(z_lo, z_hi)``: the z extent of a body's bars and bosses (m)."""
        lay = self.layers[body]
        half = 0.5 * max(lay.thickness_m, self.boss_length_m)
        return lay.z_m - half, lay.z_m + half

    def extent(self):
        """Return ``(z_lo, z_hi)``: the z extent of the whole linkage (m)."""
        slabs = [self.slab(b) for b in self.layers]
        return min(s[0] for s in slabs), max(s[1] for s in slabs)

    def pin_span(self, body_a, body_b):
        """Return ``(z_lo, z_hi)`` of the pin joining two bodies (through the layers between)."""
        lo_a, hi_a = self.slab(body_a)
        lo_b, hi_b = self.slab(body_b)
        return min(lo_a, lo_b), max(hi_a, hi_b)

    def to_dict(self):
        """Return the layers as a plain dict (SI), the form of ``build:``."""
        return {'pin_radius_m': float(self.pin_radius_m),
                'boss_length_m': float(self.boss_length_m),
                'layers': {k: {'z_m': float(v.z_m), 'thickness_m': float(v.thickness_m),
                               'bar_width_m': float(v.bar_width_m)}
                           for k, v in self.layers.items()}}


def mount_point(link, centre_m, mount=''):
    """
    Return ``(name, point)``: a disc's mount, ``mount`` or the link's point nearest its centre.

    Ties go to the first point in the link's order; ``point`` is complex (m, link frame).
    """
    if mount:
        return mount, complex(*link.points[mount])
    c = complex(*centre_m)
    best = min(link.points.items(), key=lambda kv: abs(complex(*kv[1]) - c))
    return best[0], complex(*best[1])


def stack(layers, items, side, margin_m):
    """
    Return ``{key: z_mid}``: discs stacked beyond the linkage on ``side`` (+1 above, -1 below).

    ``items``: ``[(key, thickness_m), ...]`` innermost first, each ``margin_m`` clear.
    """
    lo, hi = layers.extent()
    margin_m = margin_m + STACK_EXTRA_M
    face = hi if side > 0 else lo
    out = {}
    for key, t in items:
        out[key] = face + side * (margin_m + 0.5 * t)
        face = face + side * (margin_m + t)
    return out
