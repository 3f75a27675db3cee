"""Coarse segmentation kernels: normals, Efficient RANSAC, DBSCAN, stitching.

Not built yet: issue 4 builds them. Nothing here is importable beyond this docstring.
"""

__all__: list[str] = []
