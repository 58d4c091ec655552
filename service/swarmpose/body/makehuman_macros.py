"""MakeHuman's macro sliders (gender, ethnic share, muscle, weight, height) as target weights.

MakeHuman does not add its macro targets one by one: a slider value in 0..1 becomes the
weights of the targets at its two nearest grid points, and the weight of a combined target
is the product of its factors. With the targets the assets ship (young, caucasian only):

* gender ``g``: female ``1 - g``, male ``g``;
* ``caucasian`` ``c``: the share of the ethnic target ``caucasian-<g>-young`` (MakeHuman's
  ethnic sliders; African and Asian are not shipped). 0 leaves the base mesh's own average
  human (the ``neutral`` preset), 1 is the README's recipes;
* ``muscle`` and ``weight`` ``m, w``: 0 = min, 0.5 = average, 1 = max; the weight of
  ``universal-<g>-young-<M>muscle-<W>weight`` is gender × muscle factor × weight factor
  (the average-average target is empty, as in MakeHuman);
* ``height`` ``h``: 0 = min, 0.5 = as the other sliders make it, 1 = max, through
  ``height/<g>-young-averagemuscle-averageweight-<min|max>height`` × gender (MakeHuman would
  weigh these by the muscle and weight factors too; only the average-average pair ships).

Every preset of :data:`swarmpose.body.makehuman.PRESETS` is one point of this space
(:data:`PRESET_MACROS`), so a fit over the five numbers can reach every preset and every
blend between them. Proportion targets are not among the assets; the height slider is the
only length control.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from swarmpose.core.errors import ConfigError

_LEVELS = ("min", "average", "max")


def slider_factors(value: float) -> dict[str, float]:
    """MakeHuman's split of a 0..1 slider over its min / average / max targets (they sum to 1)."""
    v = float(np.clip(value, 0.0, 1.0))
    if v < 0.5:
        return {"min": 1.0 - 2.0 * v, "average": 2.0 * v, "max": 0.0}
    return {"min": 0.0, "average": 2.0 - 2.0 * v, "max": 2.0 * v - 1.0}


@dataclass(frozen=True)
class MacroShape:
    """The five macro sliders, each in 0..1 (see the module docstring)."""

    gender: float = 0.5
    caucasian: float = 1.0
    muscle: float = 0.5
    weight: float = 0.5
    height: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = float(getattr(self, f.name))
            if not (np.isfinite(value) and 0.0 <= value <= 1.0):
                raise ConfigError(f"MakeHuman macro {f.name} = {getattr(self, f.name)!r} must be within 0..1")
            object.__setattr__(self, f.name, value)

    @classmethod
    def from_vector(cls, x) -> MacroShape:
        """From (5,) numbers in :data:`MACRO_NAMES` order (clipped to 0..1)."""
        return cls(*(float(np.clip(v, 0.0, 1.0)) for v in np.asarray(x, float)))

    def vector(self) -> np.ndarray:
        """(5,) in :data:`MACRO_NAMES` order."""
        return np.array([getattr(self, n) for n in MACRO_NAMES])

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    def recipe(self) -> dict[str, float]:
        """{target path below targets/macrodetails (no suffix): weight} of these sliders; targets
        of weight 0 and the empty average-muscle average-weight targets are left out."""
        out: dict[str, float] = {}
        muscle, weight, height = slider_factors(self.muscle), slider_factors(self.weight), slider_factors(self.height)
        for sex, share in (("female", 1.0 - self.gender), ("male", self.gender)):
            if share <= 0:
                continue
            out[f"caucasian-{sex}-young"] = share * self.caucasian
            for m in _LEVELS:
                for w in _LEVELS:
                    if m == w == "average":
                        continue
                    out[f"universal-{sex}-young-{m}muscle-{w}weight"] = share * muscle[m] * weight[w]
            for level in ("min", "max"):
                out[f"height/{sex}-young-averagemuscle-averageweight-{level}height"] = share * height[level]
        return {k: v for k, v in out.items() if v > 0}


MACRO_NAMES = tuple(f.name for f in fields(MacroShape))

PRESET_MACROS: dict[str, MacroShape] = {
    **{g: MacroShape(gender=s) for g, s in (("male", 1.0), ("female", 0.0))},
    **{f"{g}-heavy": MacroShape(gender=s, weight=1.0) for g, s in (("male", 1.0), ("female", 0.0))},
    **{f"{g}-slim": MacroShape(gender=s, weight=0.0) for g, s in (("male", 1.0), ("female", 0.0))},
    **{f"{g}-muscular": MacroShape(gender=s, muscle=1.0) for g, s in (("male", 1.0), ("female", 0.0))},
    **{f"{g}-tall": MacroShape(gender=s, height=0.625) for g, s in (("male", 1.0), ("female", 0.0))},
    "male-short": MacroShape(gender=1.0, height=0.25),
    "female-short": MacroShape(gender=0.0, height=0.425),
    "neutral": MacroShape(caucasian=0.0),
}
"""Each preset of :data:`swarmpose.body.makehuman.PRESETS` as sliders (a tall body's max-height
target at 0.25 is ``height`` 0.625; the short ones follow ``SHORT_WEIGHT``). ``neutral`` has no
target at all: caucasian 0, the other sliders at their middle."""


def parse_macros(spec: str) -> MacroShape:
    """Sliders from ``gender=0.3,weight=0.7,...`` (any subset; the rest at :class:`MacroShape`'s
    defaults), optionally after a preset name (``female,weight=0.8``)."""
    items = [s.strip() for s in str(spec).split(",") if s.strip()]
    values = MacroShape().as_dict()
    if items and "=" not in items[0]:
        name = items.pop(0)
        if name not in PRESET_MACROS:
            raise ConfigError(f"unknown MakeHuman preset {name!r}; choose one of {', '.join(sorted(PRESET_MACROS))}")
        values = PRESET_MACROS[name].as_dict()
    for item in items:
        key, sep, raw = (s.strip() for s in item.partition("="))
        if not sep or key not in values:
            raise ConfigError(f"bad MakeHuman macro {item!r} in {spec!r}: expected key=value with key one of "
                              f"{', '.join(MACRO_NAMES)}")
        try:
            values[key] = float(raw)
        except ValueError:
            raise ConfigError(f"MakeHuman macro {key}={raw!r} is not a number") from None
    return MacroShape(**values)
