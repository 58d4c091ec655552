"""Personalisation of the built-in parametric body: :class:`BodyShape`, presets, specs.

A shape is a stature in metres, three girth factors and a sex; :func:`parse_shape` reads
one from a preset name and/or ``key=value`` overrides (the ``--shape`` option).
:mod:`swarmpose.body.parametric` builds the skinned body of a shape.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from swarmpose.core.errors import ConfigError

HEIGHT_RANGE = (1.2, 2.3)
"""Allowed stature (lo, hi), m."""
GIRTH_RANGE = (0.5, 2.0)
"""Allowed girth factors (lo, hi), unitless multipliers on cross-section radii."""
SEXES = ("neutral", "male", "female")


@dataclass(frozen=True)
class BodyShape:
    """Personalisation of the built-in body.

    height: stature in metres (1.2..2.3). torso_girth / arm_girth / leg_girth:
    multiplicative factors (0.5..2.0) on the cross-section radii of the torso (and
    neck), the arms and the legs. sex: "neutral", "male" (broader shoulders, narrower
    hips) or "female" (narrower shoulders, wider hips, slightly smaller girths).
    """

    height: float = 1.75
    torso_girth: float = 1.0
    arm_girth: float = 1.0
    leg_girth: float = 1.0
    sex: str = "neutral"

    def __post_init__(self) -> None:
        for name in ("height", "torso_girth", "arm_girth", "leg_girth"):
            try:
                object.__setattr__(self, name, float(getattr(self, name)))
            except (TypeError, ValueError):
                raise ConfigError(f"body {name} {getattr(self, name)!r} is not a number") from None
        lo, hi = HEIGHT_RANGE
        if not lo <= self.height <= hi:
            raise ConfigError(f"body height {self.height} m is outside the allowed range {lo}..{hi} m")
        lo, hi = GIRTH_RANGE
        for name in ("torso_girth", "arm_girth", "leg_girth"):
            value = getattr(self, name)
            if not lo <= value <= hi:
                raise ConfigError(f"body {name} {value} is outside the allowed range {lo}..{hi}")
        if self.sex not in SEXES:
            raise ConfigError(f"body sex {self.sex!r} is not one of {', '.join(SEXES)}")


BUILTIN_PRESETS: dict[str, BodyShape] = {
    "default": BodyShape(),
    "male": BodyShape(height=1.78, sex="male"),
    "female": BodyShape(height=1.65, sex="female"),
    "male-heavy": BodyShape(height=1.78, torso_girth=1.35, arm_girth=1.25, leg_girth=1.25, sex="male"),
    "female-slim": BodyShape(height=1.68, torso_girth=0.9, arm_girth=0.88, leg_girth=0.9, sex="female"),
    "male-tall": BodyShape(height=1.93, sex="male"),
    "female-short": BodyShape(height=1.56, sex="female"),
}

_SHAPE_KEYS = {"height": "height", "torso": "torso_girth", "arms": "arm_girth", "legs": "leg_girth", "sex": "sex"}
_SHAPE_KEYS.update({f.name: f.name for f in fields(BodyShape)})


def parse_shape(spec: str) -> BodyShape:
    """A :class:`BodyShape` from a preset name, ``key=value,...`` or a preset then overrides.

    Examples: ``"male-tall"``, ``"height=1.82,torso=1.1,arms=0.9,legs=1.0,sex=male"``,
    ``"female,height=1.60"``. Keys: height, torso, arms, legs, sex (or the field names).
    An empty spec is the default body. Raises :class:`ConfigError` on unknown presets,
    keys or values out of range.
    """
    items = [s.strip() for s in str(spec).split(",") if s.strip()]
    base = BUILTIN_PRESETS["default"]
    if items and "=" not in items[0]:
        name = items.pop(0)
        if name not in BUILTIN_PRESETS:
            raise ConfigError(f"unknown body preset {name!r}; valid presets: {', '.join(BUILTIN_PRESETS)}")
        base = BUILTIN_PRESETS[name]
    values = asdict(base)
    for item in items:
        key, sep, raw = (s.strip() for s in item.partition("="))
        if not sep or key not in _SHAPE_KEYS:
            raise ConfigError(f"bad body shape item {item!r} in {spec!r}: expected key=value with key one of "
                              f"{', '.join(_SHAPE_KEYS)}; a preset name ({', '.join(BUILTIN_PRESETS)}) "
                              "may only come first")
        field_name = _SHAPE_KEYS[key]
        if field_name == "sex":
            values[field_name] = raw
        else:
            try:
                values[field_name] = float(raw)
            except ValueError:
                raise ConfigError(f"body shape {key}={raw!r} is not a number") from None
    return BodyShape(**values)


def preset_name(shape: BodyShape) -> str | None:
    """The name of the preset equal to ``shape``, or None."""
    return next((n for n, s in BUILTIN_PRESETS.items() if s == shape), None)

