"""The verifier: re-render scenes under predicted lights (compare), image metrics,
figures (paper Figures 3-5) and the report folder."""

__all__ = [
    "compare", "figures", "imagemetrics", "probe_scenes", "report", "spheres",
]
