"""The hierarchical tree (paper: projection sequences, five-term energy, greedy recursion).

Not built yet: issue 6 builds it. Nothing here is importable beyond this docstring.
"""

__all__: list[str] = []
