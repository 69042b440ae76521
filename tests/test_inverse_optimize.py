"""Pure parts of relight.inverse.optimize: start selection, config checks, size fitting."""
from __future__ import annotations

import pytest

from relight.inverse.optimize import (DEFAULT_LEVELS, InverseError, InvertConfig, Level, fit_to_image,
                                      grid_starts, pick_starts)


def test_grid_starts_cover_the_sphere_once():
    cfg = InvertConfig(grid_pan_step_deg=90.0, grid_tilts_deg=(40.0, 70.0))
    starts = grid_starts(cfg)
    assert len(starts) == 4 * 2 + 1 and starts[-1] == (0.0, 90.0)
    assert len(set(starts)) == len(starts)


def test_pick_starts_skips_neighbours_and_clear_losers():
    cfg = InvertConfig(grid_keep=3, grid_separation_deg=45.0, grid_loss_factor=2.0)
    scored = [(1.0, 90.0, 50.0), (1.1, 90.0, 35.0), (1.5, 270.0, 50.0), (1.9, 0.0, 35.0), (2.5, 180.0, 35.0)]
    # (90, 35) is 15 deg from the best: a neighbour in the same basin, skipped
    assert pick_starts(scored, cfg) == [(90.0, 50.0), (270.0, 50.0), (0.0, 35.0)]
    # a clear winner is descended alone
    assert pick_starts([(1.0, 0.0, 40.0), (3.0, 180.0, 40.0)], cfg) == [(0.0, 40.0)]
    assert pick_starts(scored, InvertConfig(grid_keep=1)) == [(90.0, 50.0)]


def test_fit_to_image_caps_render_sizes():
    cfg = fit_to_image(InvertConfig(), 32)
    assert [lv.res for lv in cfg.levels] == [32, 32] and cfg.grid_res == 32
    assert fit_to_image(InvertConfig(), 128).levels == DEFAULT_LEVELS
    with pytest.raises(InverseError, match="square"):
        fit_to_image(InvertConfig(), 0)


def test_bad_config():
    with pytest.raises(InverseError, match="positive"):
        Level(res=32, spp=8, fd_step_deg=0.0, max_step_deg=1.0, max_iters=3, tol_deg=0.1)
    with pytest.raises(InverseError, match="level"):
        InvertConfig(levels=())
    with pytest.raises(InverseError, match="grid_pan_step_deg"):
        InvertConfig(grid_pan_step_deg=0.0)
    with pytest.raises(InverseError, match="time_budget_s"):
        InvertConfig(time_budget_s=0.0)
