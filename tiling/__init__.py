"""The store floor: the tile grid, the readers (LAS/LAZ/COPC, PLY, E57), the Zarr run store,
its lock and the ingest that tiles a scan into it.

The vocabulary every floor shares (classes, errors, column helpers) is one floor below,
in ``hollowtree.classes``, ``hollowtree.errors`` and ``hollowtree.columns``.
"""

__all__: list[str] = []
