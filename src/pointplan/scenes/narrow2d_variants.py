"""2D-Narrow variants drawn differently from the training generator, to measure how robust a policy is.

The walls are those of 2D-Narrow (a horizontal and a vertical 0.1-thick wall crossing the
unit square, their positions uniform in [0.3, 0.8]); what changes is the gaps:

- ``narrow2d-ends``: three 0.1 gaps as in 2D-Narrow (one in each half of the horizontal
  wall, one in the vertical wall above or below the crossing), but each pushed to one end
  of its wall piece: its near edge 0.025-0.05 from the square's border or from the other
  wall (2D-Narrow keeps at least 0.05). 0.025 is the disc's diameter (0.02) plus 0.005.
- ``narrow2d-many``: the three gaps of 2D-Narrow plus one or two more (4-5 gaps), each in a
  wall piece with room for it (gaps keep 0.05 from each other, the border and the crossing).
- ``narrow2d-narrow``: three gaps as in 2D-Narrow, 0.06 wide (the disc, radius 0.01, fits
  with 0.02 to spare on each side).
- ``narrow2d-manynarrow``: 4-5 gaps, 0.06 wide.

Workspace ``i`` of split ``s`` comes from ``SeedSequence([VARIANT_KEYS[name], SPLIT_KEYS[s], i])``:
streams disjoint from 2D-Narrow's own (``SeedSequence([SPLIT_KEYS[s], i])``) and from each
other. Every workspace is re-drawn until the disc's free space is one connected component
(:func:`pointplan.scenes.narrow2d.free_space_labels`, as 2D-Narrow does).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robots import Disc2D
from ..robots.base import Robot
from .base import Scenario
from .narrow2d import SPLIT_KEYS, _boxes_from_intervals, free_space_labels
from .scene import Scene

VARIANT_KEYS = {"ends": 0xE4D5, "many": 0x3A41, "narrow": 0x4A77, "manynarrow": 0x3A4A}


@dataclass(frozen=True)
class VariantConfig:
    """How a variant places its gaps."""

    #: width of each gap
    gap: float = 0.1
    #: number of gaps, drawn uniformly in [lo, hi]
    n_gaps: tuple[int, int] = (3, 3)
    #: push each of the three gaps to one end of its wall piece
    ends: bool = False
    #: distance of a pushed gap's near edge from the border or the other wall
    end_offset: tuple[float, float] = (0.025, 0.05)
    thickness: float = 0.1
    #: margin between gaps, and between a gap and the border or the crossing
    margin: float = 0.05
    wall_range: tuple[float, float] = (0.3, 0.8)


VARIANTS = {
    "ends": VariantConfig(ends=True),
    "many": VariantConfig(n_gaps=(4, 5)),
    "narrow": VariantConfig(gap=0.06),
    "manynarrow": VariantConfig(gap=0.06, n_gaps=(4, 5)),
}


def _place(rng: np.random.Generator, lo: float, hi: float, k: int, g: float, m: float) -> list[float] | None:
    """``k`` gap starts in the wall piece ``[lo, hi]``, uniformly among the placements that
    keep ``m`` from both ends and between gaps; ``None`` if they do not fit."""
    slack = (hi - lo - 2 * m) - k * g - (k - 1) * m
    if slack < 0:
        return None
    s = np.sort(rng.uniform(0.0, slack, k))
    return [lo + m + float(s[i]) + i * (g + m) for i in range(k)]


def generate_variant(rng: np.random.Generator, config: VariantConfig) -> Scene:
    """One random workspace of a variant (not yet checked for connectivity)."""
    t, g, m = config.thickness, config.gap, config.margin
    lo, hi = config.wall_range
    gy = rng.uniform(lo, hi)  # horizontal wall: y in [gy - t, gy]
    gx = rng.uniform(lo, hi)  # vertical wall: x in [gx - t, gx]
    # the four wall pieces: (wall axis, lower end, upper end)
    pieces = {"left": (0, 0.0, gx - t), "right": (0, gx, 1.0), "below": (1, 0.0, gy - t), "above": (1, gy, 1.0)}
    vertical = "below" if rng.random() < 0.5 else "above"
    count = {"left": 1, "right": 1, "below": 0, "above": 0}
    count[vertical] = 1
    n = int(rng.integers(config.n_gaps[0], config.n_gaps[1] + 1))
    for _ in range(n - 3):  # extra gaps go to pieces with room for one more
        room = [p for p in pieces if (pieces[p][2] - pieces[p][1] - 2 * m) - (count[p] + 1) * g - count[p] * m >= 0]
        if not room:
            break
        count[room[int(rng.integers(len(room)))]] += 1
    holes: dict[int, list[tuple[float, float]]] = {0: [], 1: []}
    for p, (axis, a, b) in pieces.items():
        if count[p] == 0:
            continue
        if config.ends:  # one gap, pushed to the border end or the crossing end of the piece
            off = rng.uniform(*config.end_offset)
            start = a + off if rng.random() < 0.5 else b - off - g
            starts = [start]
        else:
            starts = _place(rng, a, b, count[p], g, m) or []
        holes[axis] += [(s, s + g) for s in starts]
    obstacles = _boxes_from_intervals(0, gy - t, gy, holes[0])
    obstacles += _boxes_from_intervals(1, gx - t, gx, holes[1])
    return Scene(obstacles=obstacles, low=np.zeros(2), high=np.ones(2), name="narrow2d-variant")


def variant_workspace(variant: str, split: str, index: int, radius: float = 0.01) -> Scene:
    """Workspace ``index`` of ``split`` of a variant; re-drawn until connected."""
    if split not in SPLIT_KEYS:
        raise ValueError(f"unknown split {split!r}; use 'train', 'val' or 'test'")
    config = VARIANTS[variant]
    rng = np.random.default_rng(np.random.SeedSequence([VARIANT_KEYS[variant], SPLIT_KEYS[split], int(index)]))
    for _ in range(100):
        scene = generate_variant(rng, config)
        if free_space_labels(scene, radius)[1] == 1:
            scene.name = f"narrow2d-{variant}/{split}/{index}"
            return scene
    raise RuntimeError(f"narrow2d-{variant} kept producing disconnected workspaces")


class Narrow2DVariantScenario(Scenario):
    """A 2D-Narrow variant with the 2D disc; horizon 50 (as 2D-Narrow)."""

    variant = ""
    horizon = 50

    def __init__(self, robot: Robot | None = None) -> None:
        self.robot = robot or Disc2D()
        self.name = f"narrow2d-{self.variant}"

    def scene(self, split: str, index: int) -> Scene:
        return variant_workspace(self.variant, split, index, radius=float(self.robot.parts.sphere_radii.max()))


class Narrow2DEnds(Narrow2DVariantScenario):
    """Three gaps pushed to the ends of their wall pieces."""

    variant = "ends"


class Narrow2DMany(Narrow2DVariantScenario):
    """Four or five 0.1 gaps."""

    variant = "many"


class Narrow2DNarrowGaps(Narrow2DVariantScenario):
    """Three 0.06 gaps."""

    variant = "narrow"


class Narrow2DManyNarrow(Narrow2DVariantScenario):
    """Four or five 0.06 gaps."""

    variant = "manynarrow"


#: registry keys (as :func:`pointplan.scenes.registry.scenario_key` spells ``narrow2d-ends``)
VARIANT_SCENARIOS: dict[str, type[Scenario]] = {
    "narrow2dends": Narrow2DEnds,
    "narrow2dmany": Narrow2DMany,
    "narrow2dnarrow": Narrow2DNarrowGaps,
    "narrow2dmanynarrow": Narrow2DManyNarrow,
}
#: the names users type, by registry key (``narrow2dends`` -> ``narrow2d-ends``)
VARIANT_NAMES: dict[str, str] = {f"narrow2d{v}": f"narrow2d-{v}" for v in VARIANTS}
