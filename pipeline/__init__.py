"""Orchestration: the command line now; per-unit Dask tasks and workflows in later issues."""

__all__: list[str] = []
