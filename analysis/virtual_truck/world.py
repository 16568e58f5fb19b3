"""The world a scenario is driven in, by realism level: the ideal road or terrain with a road built in."""

from __future__ import annotations

from .realistic_road import engineered_road
from .realism import IDEAL, Realism
from .road import Road, ideal_road
from .scenario import Scenario


def build_road(scenario: Scenario, seed: int = 0, realism: Realism = IDEAL) -> Road:
    """The road and terrain of ``scenario`` for ``seed`` (same seed, same world).

    The ideal level builds the terrain around the road (`road.ideal_road`: the DEM is the road plus
    ``cut_fill``); realistic levels build terrain first and engineer the road into it
    (`realistic_road.engineered_road`).
    """
    if realism.terrain_first:
        return engineered_road(scenario, seed)
    return ideal_road(scenario, seed)
