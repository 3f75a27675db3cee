"""The hierarchical tree (paper: projection sequences, five-term energy, greedy recursion).

- :mod:`tree.operators`: ``v1``, ``psi`` (circle and n-gon RANSAC), ``p``, ``u``, ``h``,
  ``v2``, ``rho`` as pure NumPy/SciPy kernels;
- :mod:`tree.sequences`: ``S1``, ``S2``, ``S3`` and the storeys proposing splits of one node;
- :mod:`tree.energy`: ``e1``..``e5``, ``xi = w . e`` and the versioned energy model;
- :mod:`tree.build`: Algorithm 1 on one segment (:func:`build_tree`);
- :mod:`tree.split`: the learned split decision (the pipeline's default) and its model file;
- :mod:`tree.fit`: the regression of ``w`` and the prior ``W`` on synthetic scenes;
- :mod:`tree.fit_split`: the fit of the split model.

The per-segment Dask tasks and the CLI live in ``pipeline/``.
"""

from hollowtree.exports import lazy_exports

# Imported on first use: ``hollowtree.tree.build_params`` stays light (no NumPy).
__all__, __getattr__ = lazy_exports(__name__, {
    "build": "NodeTable TreeResult build_tree",
    "energy": "Classifier EnergyModel e1 e2 e3 e4 e5 energy_terms load_energy_model",
    "operators": "TransportCurve fit_circle fit_ngon h p psi rho u v1 v2",
    "sequences": "Proposal SequenceParams propose s1 s2 s3 storeys",
    "split": "SplitModel load_split_model split_features",
})
