"""Drawings of planning problems (matplotlib, Agg canvas; never opens a window)."""

from .plot2d import draw_problem, grid_figsize, render_grid, render_problem, render_rgb

__all__ = ["draw_problem", "grid_figsize", "render_grid", "render_problem", "render_rgb"]
