"""HollowNet: hollow voxels and the 3D CNN that classifies segments.

Not built yet: issue 5 builds it. Nothing here is importable beyond this docstring.
"""

__all__: list[str] = []
