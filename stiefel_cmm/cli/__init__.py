"""Command-line front door: ``stiefel modes | eigs | compare-smoothings | view``.

The CLI sits on top of the layers (``mesh``, ``objectives``, ``stiefel``) and is
the only place that switches JAX to float64 (``jax_enable_x64``, in ``main``).
Modules: ``stiefel_cmm.cli.main`` (argument parsing, signals, exit codes), ``stiefel_cmm.cli.commands``
(the three subcommands), ``stiefel_cmm.cli.run_dir`` (atomic output directories: staging,
fsync, commit with ``summary.json`` last, lock), ``stiefel_cmm.cli.demo_mesh`` (the built-in
demo surface), ``stiefel_cmm.cli.outputs`` (npz / PLY writers, μ parsing, provenance),
``stiefel_cmm.cli.render`` and ``stiefel_cmm.cli.render_views`` (PNG contact sheets: principal-axes orientation, views, z-buffer
rasteriser), ``stiefel_cmm.cli.viewer`` (self-contained HTML viewer, ``stiefel view``), ``stiefel_cmm.cli.options`` (the options
and their API names), ``stiefel_cmm.cli.compare`` (``compare-smoothings``).
"""

__all__: list[str] = []
