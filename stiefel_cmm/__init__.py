"""The ``stiefel-cmm`` distribution's application layer: the ``stiefel`` command (``stiefel_cmm.cli``).

The libraries are the top-level packages ``stiefel`` (manifolds and solvers), ``mesh`` (meshes and
Laplacians) and ``objectives`` (compressed manifold modes); ``python -m stiefel_cmm`` is the command.
"""
