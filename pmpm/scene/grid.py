"""The scene's ``[grid]`` table (read by pmpm.scene.config and by the frame front end,
pmpm.scene.frame, which sizes members against it)."""
import math
from dataclasses import dataclass

from pmpm.errors import ConfigError
from pmpm.scene.tables import MAX_MAGNITUDE

__all__ = ["GridConfig", "parse_grid", "MAX_CELLS_PER_AXIS"]


@dataclass(frozen=True)
class GridConfig:
    origin: tuple
    cell_size: float
    cells: tuple


#: most cells along one axis: node indices and counts stay far inside int32/int64 arithmetic
MAX_CELLS_PER_AXIS = 2 ** 31 - 2


def parse_grid(t):
    """``[grid]``: origin, cell size and cells, checked (the extent finite, positions resolving h)."""
    g = GridConfig(origin=t.vector("origin", (0.0, 0.0)),
                   cell_size=t.number("cell_size", low=0, low_open=True),
                   cells=t.int_vector("cells", low=3))
    if max(g.cells) > MAX_CELLS_PER_AXIS:
        raise ConfigError(t.path("cells"), f"at most {MAX_CELLS_PER_AXIS} cells per axis (integer range)")
    for d in range(2):
        upper = g.origin[d] + g.cell_size * g.cells[d]
        if not (math.isfinite(upper) and abs(upper) <= MAX_MAGNITUDE):  # squared in the set-up
            raise ConfigError(t.path("cells"), f"the grid's extent (cells x cell_size) is not a finite "
                                               f"number of at most {MAX_MAGNITUDE:g}")
        # positions must resolve the cell size: x + h must differ from x across the whole grid
        if g.cell_size < 1e-9 * max(abs(g.origin[d]), abs(upper)):
            raise ConfigError(t.path("cell_size"), "too small for the grid's coordinates "
                                                   "(below 1e-9 of their magnitude)")
    t.finish()
    return g
