"""Geometry building blocks: SE(3) helpers, minimum enclosing ball, SO(3) grid, octree, SOCP box."""
